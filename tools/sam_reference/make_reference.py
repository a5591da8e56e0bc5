#!/usr/bin/python3
"""Reference outputs for hgs's native SAM (tests/sam). Run by hand, never by CI:

    /usr/bin/python3 tools/sam_reference/make_reference.py [OUT_DIR]   # default tests/data/sam

Needs Debian's python3-torch and python3-numpy (not installed by scripts/setup: the committed fixtures are what
the tests read). This is an own PyTorch implementation of SAM written after the Hugging Face transformers
`SamModel` (tensor names vision_encoder.*, prompt_encoder.*, mask_decoder.*, shared_image_embedding.*) and
segment-anything: ViT image encoder with windowed / global attention and decomposed relative positions, neck,
random-Fourier positional encoding, point / box prompt encoder, two-way transformer mask decoder with output
upscaling, hypernetwork MLPs and IoU head, and the mask post-processing. No hub downloads: the weights are
tiny and random (seeded), stored as F16 safetensors (the model computes with the F16-rounded values in float32).

Tiny model: ViT hidden 32, 3 layers (layer 1 global, the others windowed with window 3 on an 8x8 grid, so
windows are padded to 9x9), 2 heads, MLP 96, patch 8, image size 64; neck / prompt / decoder width 32,
decoder 2 layers, 8 heads, MLP 64, IoU head 3 layers of 24.

Writes into OUT_DIR: tiny_sam.safetensors and
  image.npy [45, 70, 3] uint8 raw image (/ 255 gives the [0, 1] input);  pixels.npy [64, 64, 3] preprocessed (resized, normalised, padded)
  patch.npy [8, 8, 32] patch embedding + pos_embed;  layer{i}.npy [8, 8, 32] after each ViT layer
  embedding.npy [8, 8, 32] neck output (the image embedding, HWC);  dense_pe.npy [8, 8, 32]
  prompts.json: the prompt sets (points in original image pixels, labels, boxes)
  per prompt set k: sparse{k}.npy [T, 32], lowres{k}.npy [4, 32, 32] (all 4 mask tokens), iou{k}.npy [4],
  masks3.npy [4, 45, 70] (prompt set 3) logits post-processed to the original image size.
  amg.json (options, and per kept mask: bbox XYWH, area, predicted_iou, stability_score, point_coords) and
  amg_masks.npy [K, 45, 70] uint8: the automatic mask generator on a 5 x 5 grid (batches of 7) with lowered
  thresholds (random weights predict low IoUs).

Pruned model (CFG_PRUNED, like SlimSAM's pruned checkpoints: the residual width stays 32, every ViT layer has
its own heads x head dim and MLP width: 2 x 6 / 40, 4 x 5 / 24 (the global layer), 1 x 16 / 72; the attention
scale is each layer's head dim ** -0.5; prompt encoder and decoder as above; own seed), into OUT_DIR/pruned:
pruned_sam.safetensors and the same stages for the same image and prompt sets (image.npy, pixels.npy and
prompts.json are the tiny model's), low-res masks of prompt sets 1 and 3 only (size).
"""
import json
import math
import os
import struct
import sys

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
OUT = os.path.abspath(sys.argv[1]) if len(sys.argv) > 1 else os.path.join(ROOT, "tests", "data", "sam")

MEAN = (0.485, 0.456, 0.406)
STD = (0.229, 0.224, 0.225)

CFG = dict(hidden=32, layers=3, heads=2, mlp=96, patch=8, image=64, window=3, global_layers=[1],
           out=32, dec_layers=2, dec_heads=8, dec_mlp=64, iou_hidden=24, iou_depth=3)

# Pruned like SlimSAM: one residual width (32), every layer its own heads x head dim (attention widths 12, 20,
# 16) and MLP width; the layers' head dims differ so that their relative-position tables do too.
CFG_PRUNED = dict(CFG, layer_heads=[2, 4, 1], layer_head_dims=[6, 5, 16], layer_mlp=[40, 24, 72])

# ------------------------------------------------------------------------------------------------ modules


class LayerNorm2d(nn.Module):
    """LayerNorm over the channel axis of [B, C, H, W] (SamLayerNorm channels_first, eps 1e-6)."""

    def __init__(self, c, eps=1e-6):
        super().__init__()
        self.weight = nn.Parameter(torch.ones(c))
        self.bias = nn.Parameter(torch.zeros(c))
        self.eps = eps

    def forward(self, x):
        u = x.mean(1, keepdim=True)
        s = (x - u).pow(2).mean(1, keepdim=True)
        x = (x - u) / torch.sqrt(s + self.eps)
        return self.weight[:, None, None] * x + self.bias[:, None, None]


class MLP2(nn.Module):
    def __init__(self, d, h, act):
        super().__init__()
        self.lin1 = nn.Linear(d, h)
        self.lin2 = nn.Linear(h, d)
        self.act = act

    def forward(self, x):
        return self.lin2(self.act(self.lin1(x)))


def rel_table(q, k, rel):
    """Relative position rows R[q, k, C] = rel[(qi - ki) + k - 1] (q == k in SAM; no resizing needed)."""
    assert q == k and rel.shape[0] == 2 * q - 1
    idx = torch.arange(q)[:, None] - torch.arange(k)[None, :] + (k - 1)
    return rel[idx]


class VisionAttention(nn.Module):
    """Attention of width heads * hd (dim // heads unless a pruned layer gives its own head dim hd), scale
    hd ** -0.5 (SlimSAM resets it to the pruned head dim)."""

    def __init__(self, dim, heads, size, hd=None):
        super().__init__()
        self.heads = heads
        hd = dim // heads if hd is None else hd
        self.scale = hd ** -0.5
        self.qkv = nn.Linear(dim, 3 * heads * hd)
        self.proj = nn.Linear(heads * hd, dim)
        self.rel_pos_h = nn.Parameter(torch.zeros(2 * size - 1, hd))
        self.rel_pos_w = nn.Parameter(torch.zeros(2 * size - 1, hd))

    def forward(self, x):  # [B, H, W, C]
        B, H, W, C = x.shape
        qkv = self.qkv(x).reshape(B, H * W, 3, self.heads, -1).permute(2, 0, 3, 1, 4)
        q, k, v = qkv.reshape(3, B * self.heads, H * W, -1).unbind(0)
        attn = (q * self.scale) @ k.transpose(-2, -1)
        Rh = rel_table(H, H, self.rel_pos_h)
        Rw = rel_table(W, W, self.rel_pos_w)
        rq = q.reshape(B * self.heads, H, W, -1)
        rel_h = torch.einsum("bhwc,hkc->bhwk", rq, Rh)
        rel_w = torch.einsum("bhwc,wkc->bhwk", rq, Rw)
        attn = (attn.view(-1, H, W, H, W) + rel_h[:, :, :, :, None] + rel_w[:, :, :, None, :]).view(-1, H * W, H * W)
        attn = attn.softmax(dim=-1)
        x = (attn @ v).view(B, self.heads, H, W, -1).permute(0, 2, 3, 1, 4).reshape(B, H, W, -1)
        return self.proj(x)


class VisionLayer(nn.Module):
    def __init__(self, dim, heads, mlp, window, grid, hd=None):
        super().__init__()
        self.layer_norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = VisionAttention(dim, heads, window if window > 0 else grid, hd)
        self.layer_norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = MLP2(dim, mlp, nn.GELU())
        self.window = window

    def forward(self, x):  # [B, H, W, C]
        shortcut = x
        x = self.layer_norm1(x)
        if self.window > 0:
            B, H, W, C = x.shape
            w = self.window
            ph, pw = (w - H % w) % w, (w - W % w) % w
            x = F.pad(x, (0, 0, 0, pw, 0, ph))  # zeros after the norm; padded tokens take part as keys
            Hp, Wp = H + ph, W + pw
            x = x.view(B, Hp // w, w, Wp // w, w, C).permute(0, 1, 3, 2, 4, 5).reshape(-1, w, w, C)
            x = self.attn(x)
            x = x.view(B, Hp // w, Wp // w, w, w, C).permute(0, 1, 3, 2, 4, 5).reshape(B, Hp, Wp, C)
            x = x[:, :H, :W, :]
        else:
            x = self.attn(x)
        x = shortcut + x
        return x + self.mlp(self.layer_norm2(x))


class Neck(nn.Module):
    def __init__(self, dim, out):
        super().__init__()
        self.conv1 = nn.Conv2d(dim, out, 1, bias=False)
        self.layer_norm1 = LayerNorm2d(out)
        self.conv2 = nn.Conv2d(out, out, 3, padding=1, bias=False)
        self.layer_norm2 = LayerNorm2d(out)

    def forward(self, x):  # [B, H, W, C] -> [B, out, H, W]
        x = x.permute(0, 3, 1, 2)
        return self.layer_norm2(self.conv2(self.layer_norm1(self.conv1(x))))


class PatchEmbed(nn.Module):
    def __init__(self, dim, patch):
        super().__init__()
        self.projection = nn.Conv2d(3, dim, patch, stride=patch)


class VisionEncoder(nn.Module):
    def __init__(self, c):
        super().__init__()
        g = c["image"] // c["patch"]
        self.patch_embed = PatchEmbed(c["hidden"], c["patch"])
        self.pos_embed = nn.Parameter(torch.zeros(1, g, g, c["hidden"]))
        # A pruned model (SlimSAM) gives each layer its own heads, head dim and MLP width.
        self.layers = nn.ModuleList([
            VisionLayer(c["hidden"], c["layer_heads"][i] if "layer_heads" in c else c["heads"],
                        c["layer_mlp"][i] if "layer_mlp" in c else c["mlp"],
                        0 if i in c["global_layers"] else c["window"], g,
                        c["layer_head_dims"][i] if "layer_head_dims" in c else None)
            for i in range(c["layers"])])
        self.neck = Neck(c["hidden"], c["out"])

    def forward(self, px):  # [B, 3, S, S]
        x = self.patch_embed.projection(px).permute(0, 2, 3, 1) + self.pos_embed
        stages = [x]
        for l in self.layers:
            x = l(x)
            stages.append(x)
        return self.neck(x), stages


class PositionalEmbedding(nn.Module):
    """Random Fourier features: coords in [0, 1]^2 -> [sin(2 pi (2c - 1) G), cos(...)]."""

    def __init__(self, feats):
        super().__init__()
        self.register_buffer("positional_embedding", torch.randn(2, feats))

    def forward(self, coords, input_shape=None):
        c = coords.clone()
        if input_shape is not None:
            c[..., 0] = c[..., 0] / input_shape[1]
            c[..., 1] = c[..., 1] / input_shape[0]
        c = 2 * c - 1
        c = 2 * math.pi * (c @ self.positional_embedding)
        return torch.cat([torch.sin(c), torch.cos(c)], dim=-1)


class PromptEncoder(nn.Module):
    def __init__(self, c, shared):
        super().__init__()
        self.shared = [shared]  # not a submodule: its tensor is saved once, as shared_image_embedding.*
        self.input_size = c["image"]
        self.point_embed = nn.ModuleList([nn.Embedding(1, c["out"]) for _ in range(4)])
        self.not_a_point_embed = nn.Embedding(1, c["out"])
        self.no_mask_embed = nn.Embedding(1, c["out"])

    def forward(self, points, labels, boxes):
        """points [N, 2] (input-image pixels), labels [N], boxes [M, 4] -> sparse [T, C]."""
        out = []
        S = (self.input_size, self.input_size)
        if points is not None:
            p = points + 0.5
            lab = labels
            if boxes is None:
                p = torch.cat([p, torch.zeros(1, 2)], 0)
                lab = torch.cat([lab, -torch.ones(1, dtype=lab.dtype)], 0)
            e = self.shared[0](p, S)
            e[lab == -1] = 0.0
            e[lab == -1] += self.not_a_point_embed.weight[0]
            e[lab == 0] += self.point_embed[0].weight[0]
            e[lab == 1] += self.point_embed[1].weight[0]
            out.append(e)
        if boxes is not None:
            b = (boxes + 0.5).reshape(-1, 2, 2)
            e = self.shared[0](b, S)
            e[:, 0, :] += self.point_embed[2].weight[0]
            e[:, 1, :] += self.point_embed[3].weight[0]
            out.append(e.reshape(-1, e.shape[-1]))
        return torch.cat(out, 0)


class Attention(nn.Module):
    def __init__(self, dim, heads, down=1):
        super().__init__()
        inner = dim // down
        self.heads = heads
        self.q_proj = nn.Linear(dim, inner)
        self.k_proj = nn.Linear(dim, inner)
        self.v_proj = nn.Linear(dim, inner)
        self.out_proj = nn.Linear(inner, dim)

    def forward(self, q, k, v):  # [B, N, C]
        q, k, v = self.q_proj(q), self.k_proj(k), self.v_proj(v)
        B, Nq, I = q.shape
        h = self.heads
        q = q.view(B, Nq, h, -1).transpose(1, 2)
        k = k.view(B, k.shape[1], h, -1).transpose(1, 2)
        v = v.view(B, v.shape[1], h, -1).transpose(1, 2)
        a = (q @ k.transpose(-2, -1)) / math.sqrt(q.shape[-1])
        a = a.softmax(dim=-1)
        o = (a @ v).transpose(1, 2).reshape(B, Nq, I)
        return self.out_proj(o)


class TwoWayBlock(nn.Module):
    def __init__(self, dim, heads, mlp, skip_pe):
        super().__init__()
        self.self_attn = Attention(dim, heads)
        self.layer_norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.cross_attn_token_to_image = Attention(dim, heads, 2)
        self.layer_norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = MLP2(dim, mlp, nn.ReLU())
        self.layer_norm3 = nn.LayerNorm(dim, eps=1e-6)
        self.layer_norm4 = nn.LayerNorm(dim, eps=1e-6)
        self.cross_attn_image_to_token = Attention(dim, heads, 2)
        self.skip_pe = skip_pe

    def forward(self, q, k, qpe, kpe):
        if self.skip_pe:
            q = self.self_attn(q, q, q)
        else:
            qq = q + qpe
            q = q + self.self_attn(qq, qq, q)
        q = self.layer_norm1(q)
        q = self.layer_norm2(q + self.cross_attn_token_to_image(q + qpe, k + kpe, k))
        q = self.layer_norm3(q + self.mlp(q))
        k = self.layer_norm4(k + self.cross_attn_image_to_token(k + kpe, q + qpe, q))
        return q, k


class TwoWayTransformer(nn.Module):
    def __init__(self, c):
        super().__init__()
        d = c["out"]
        self.layers = nn.ModuleList([TwoWayBlock(d, c["dec_heads"], c["dec_mlp"], i == 0) for i in range(c["dec_layers"])])
        self.final_attn_token_to_image = Attention(d, c["dec_heads"], 2)
        self.layer_norm_final_attn = nn.LayerNorm(d)  # default eps 1e-5, as in transformers

    def forward(self, img, pe, tokens):  # img, pe [B, HW, C]; tokens [B, T, C]
        q, k = tokens, img
        for l in self.layers:
            q, k = l(q, k, tokens, pe)
        q = self.layer_norm_final_attn(q + self.final_attn_token_to_image(q + tokens, k + pe, k))
        return q, k


class FeedForward(nn.Module):
    def __init__(self, i, h, o, n):
        super().__init__()
        self.proj_in = nn.Linear(i, h)
        self.layers = nn.ModuleList([nn.Linear(h, h) for _ in range(n - 2)])
        self.proj_out = nn.Linear(h, o)

    def forward(self, x):
        x = F.relu(self.proj_in(x))
        for l in self.layers:
            x = F.relu(l(x))
        return self.proj_out(x)


class MaskDecoder(nn.Module):
    def __init__(self, c):
        super().__init__()
        d = c["out"]
        self.iou_token = nn.Embedding(1, d)
        self.mask_tokens = nn.Embedding(4, d)
        self.transformer = TwoWayTransformer(c)
        self.upscale_conv1 = nn.ConvTranspose2d(d, d // 4, 2, stride=2)
        self.upscale_layer_norm = LayerNorm2d(d // 4)
        self.upscale_conv2 = nn.ConvTranspose2d(d // 4, d // 8, 2, stride=2)
        self.output_hypernetworks_mlps = nn.ModuleList([FeedForward(d, d, d // 8, 3) for _ in range(4)])
        self.iou_prediction_head = FeedForward(d, c["iou_hidden"], 4, c["iou_depth"])

    def forward(self, emb, pe, sparse, dense):
        """emb, pe, dense [C, h, w]; sparse [T, C] -> masks [4, 4h, 4w], iou [4] (all four mask tokens)."""
        C, h, w = emb.shape
        tokens = torch.cat([self.iou_token.weight, self.mask_tokens.weight, sparse], 0)[None]
        src = (emb + dense).reshape(C, h * w).t()[None]
        pos = pe.reshape(C, h * w).t()[None]
        hs, src = self.transformer(src, pos, tokens)
        src = src.transpose(1, 2).reshape(1, C, h, w)
        up = F.gelu(self.upscale_layer_norm(self.upscale_conv1(src)))
        up = F.gelu(self.upscale_conv2(up))
        hyper = torch.stack([m(hs[:, 1 + i]) for i, m in enumerate(self.output_hypernetworks_mlps)], 1)
        masks = (hyper @ up.reshape(1, up.shape[1], -1)).reshape(4, up.shape[2], up.shape[3])
        return masks, self.iou_prediction_head(hs[0, 0])


class Sam(nn.Module):
    def __init__(self, c):
        super().__init__()
        self.c = c
        self.shared_image_embedding = PositionalEmbedding(c["out"] // 2)
        self.vision_encoder = VisionEncoder(c)
        self.prompt_encoder = PromptEncoder(c, self.shared_image_embedding)
        self.mask_decoder = MaskDecoder(c)

    def dense_pe(self):
        g = self.c["image"] // self.c["patch"]
        grid = torch.ones(g, g)
        y = (grid.cumsum(0) - 0.5) / g
        x = (grid.cumsum(1) - 0.5) / g
        return self.shared_image_embedding(torch.stack([x, y], -1)).permute(2, 0, 1)  # [C, g, g]


# ------------------------------------------------------------------------------------------ pre/post-process


def preprocess_shape(h, w, longest):
    s = longest / max(h, w)
    return int(h * s + 0.5), int(w * s + 0.5)


def preprocess(img, S):
    """img [H, W, 3] in [0, 1] -> [3, S, S]: antialiased bilinear resize of the longest side to S, mean/std,
    zero padding right / bottom."""
    h, w = preprocess_shape(img.shape[0], img.shape[1], S)
    x = torch.from_numpy(img).double().permute(2, 0, 1)[None]
    x = F.interpolate(x, size=(h, w), mode="bilinear", antialias=True, align_corners=False)[0]
    x = (x - torch.tensor(MEAN, dtype=torch.float64)[:, None, None]) / torch.tensor(STD, dtype=torch.float64)[:, None, None]
    out = torch.zeros(3, S, S, dtype=torch.float64)
    out[:, :h, :w] = x
    return out.float(), (h, w)


def postprocess(masks, S, hw, orig):
    """masks [N, s, s] low-res logits -> [N, H, W]: bilinear to S x S, crop to the resized image, bilinear to the
    original size (align_corners False, as segment-anything and transformers)."""
    m = F.interpolate(masks[None], size=(S, S), mode="bilinear", align_corners=False)
    m = m[..., :hw[0], :hw[1]]
    return F.interpolate(m, size=orig, mode="bilinear", align_corners=False)[0]


def automatic_masks(model, emb, pe, dense, S, hw, orig, o):
    """segment-anything's automatic mask generator with one crop (the whole image): grid points, all three
    multimask outputs, predicted-IoU and stability filters, binarise, boxes, greedy box NMS."""
    H, W = orig
    n = o["points_per_side"]
    off = 1.0 / (2 * n)
    side = np.linspace(off, 1 - off, n)
    grid = np.stack([np.tile(side[None, :], (n, 1)), np.tile(side[:, None], (1, n))], -1).reshape(-1, 2)
    pts = grid * np.array([W, H])
    keep_masks, boxes, scores, stabs, points = [], [], [], [], []
    for b0 in range(0, len(pts), o["points_per_batch"]):
        for pt in pts[b0:b0 + o["points_per_batch"]]:
            p_in = torch.tensor(pt * np.array([hw[1] / W, hw[0] / H]), dtype=torch.float32)[None]
            sparse = model.prompt_encoder(p_in, torch.tensor([1]), None)
            masks, iou = model.mask_decoder(emb, pe, sparse, dense)
            full = postprocess(masks[1:], S, hw, orig)
            for t in range(3):
                if not iou[1 + t] > o["pred_iou_thresh"]:
                    continue
                m = full[t]
                inter = (m > o["offset"]).sum().item()
                union = (m > -o["offset"]).sum().item()
                stab = inter / union if union else 0.0
                if not stab > o["stability_thresh"]:
                    continue
                binm = m > 0
                ys, xs = torch.nonzero(binm, as_tuple=True)
                box = [0, 0, 0, 0] if len(xs) == 0 else [xs.min().item(), ys.min().item(), xs.max().item(), ys.max().item()]
                keep_masks.append(binm)
                boxes.append(box)
                scores.append(iou[1 + t].item())
                stabs.append(stab)
                points.append(pt.tolist())
    order = sorted(range(len(scores)), key=lambda i: -scores[i])
    kept = []
    for i in order:
        a = boxes[i]
        ok = True
        for k in kept:
            b = boxes[k]
            iw = max(0, min(a[2], b[2]) - max(a[0], b[0]))
            ih = max(0, min(a[3], b[3]) - max(a[1], b[1]))
            inter = iw * ih
            uni = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
            if uni > 0 and inter / uni > o["box_nms_thresh"]:
                ok = False
                break
        if ok:
            kept.append(i)
    anns = [{"bbox": [boxes[i][0], boxes[i][1], boxes[i][2] - boxes[i][0], boxes[i][3] - boxes[i][1]],
             "area": int(keep_masks[i].sum().item()), "predicted_iou": scores[i], "stability_score": stabs[i],
             "point_coords": [points[i]]} for i in kept]
    masks = np.stack([keep_masks[i].numpy().astype(np.uint8) for i in kept]) if kept else np.zeros((0, H, W), np.uint8)
    return anns, masks


AMG = dict(points_per_side=5, points_per_batch=7, pred_iou_thresh=0.55, stability_thresh=0.02, offset=0.25,
           box_nms_thresh=1.0)

# ------------------------------------------------------------------------------------------------ output


def save_safetensors(path, tensors, dtype="F16"):
    header, blobs, off = {}, [], 0
    for name, t in tensors.items():
        a = t.detach().cpu().numpy().astype(np.float16 if dtype == "F16" else np.float32)
        b = a.tobytes()
        header[name] = {"dtype": dtype, "shape": list(a.shape), "data_offsets": [off, off + len(b)]}
        blobs.append(b)
        off += len(b)
    header["__metadata__"] = {"format": "pt"}
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * ((8 - len(h) % 8) % 8)
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(h)))
        f.write(h)
        for b in blobs:
            f.write(b)


def save(name, t):
    np.save(os.path.join(OUT, name), np.ascontiguousarray(t.detach().cpu().numpy().astype(np.float32)))


def make_model(c, seed):
    torch.manual_seed(seed)
    model = Sam(c).eval()
    sd = {}
    with torch.no_grad():
        for name, p in list(model.named_parameters()) + list(model.named_buffers()):
            # Random weights of a scale that keeps activations O(1); biases and norms non-trivial.
            if name.endswith("positional_embedding"):
                p.copy_(torch.randn_like(p) * 1.5)
            elif p.dim() == 1:
                base = 1.0 if ("layer_norm" in name and name.endswith("weight")) else 0.0
                p.copy_(base + 0.2 * torch.randn_like(p))
            elif "rel_pos" in name:
                p.copy_(0.5 * torch.randn_like(p))
            elif name.endswith("pos_embed") or "embed" in name.split(".")[-2] or name.endswith("token.weight") or name.endswith("tokens.weight"):
                p.copy_(torch.randn_like(p))
            else:
                fan_in = p[0].numel() if "upscale_conv" not in name else p.shape[0]
                p.copy_(torch.randn_like(p) * (1.2 / math.sqrt(fan_in)))
            p.copy_(p.half().float())  # the model computes with the F16 values it saves
            sd[name] = p
    return model, sd


def test_image():
    H, W = 45, 70
    yy, xx = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    rng = np.random.default_rng(7)
    img = np.stack([0.5 + 0.4 * np.sin(xx / 7.0 + k) * np.cos(yy / 5.0 - k) for k in range(3)], -1)
    return np.round(255 * np.clip(img + 0.05 * rng.standard_normal(img.shape), 0, 1)).astype(np.uint8)


PROMPTS = [
    {"points": [[30.0, 20.0]], "labels": [1]},
    {"points": [[12.5, 8.0], [60.0, 40.0]], "labels": [1, 0]},
    {"boxes": [[5.0, 4.0, 50.0, 33.0]]},
    {"points": [[40.0, 25.0]], "labels": [1], "boxes": [[20.0, 10.0, 66.0, 42.0]]},
]


def write_outputs(model, c, img8, full=True, lowres_sets=(0, 1, 2, 3)):
    """Every stage's outputs into OUT. full=False leaves out what does not depend on the model (the image, the
    preprocessed pixels, the prompt sets: the tiny model's files)."""
    S = c["image"]
    H, W = img8.shape[:2]
    if full:
        np.save(os.path.join(OUT, "image.npy"), img8)
    img = img8.astype(np.float32) / 255.0

    with torch.no_grad():
        px, hw = preprocess(img, S)
        if full:
            save("pixels.npy", px.permute(1, 2, 0))
        emb, stages = model.vision_encoder(px[None])
        save("patch.npy", stages[0][0])
        for i, s in enumerate(stages[1:]):
            save(f"layer{i}.npy", s[0])
        save("embedding.npy", emb[0].permute(1, 2, 0))
        pe = model.dense_pe()
        save("dense_pe.npy", pe.permute(1, 2, 0))
        dense = model.prompt_encoder.no_mask_embed.weight[0][:, None, None].expand_as(pe)

        sy, sx = hw[0] / H, hw[1] / W  # original pixels -> input pixels
        prompts = PROMPTS
        for k, pr in enumerate(prompts):
            pts = lab = box = None
            if "points" in pr:
                pts = torch.tensor(pr["points"]) * torch.tensor([sx, sy])
                lab = torch.tensor(pr["labels"])
            if "boxes" in pr:
                box = torch.tensor(pr["boxes"]) * torch.tensor([sx, sy, sx, sy])
            sparse = model.prompt_encoder(pts, lab, box)
            save(f"sparse{k}.npy", sparse)
            masks, iou = model.mask_decoder(emb[0], pe, sparse, dense)
            if k in lowres_sets:
                save(f"lowres{k}.npy", masks)
            save(f"iou{k}.npy", iou)
            if k == 3:  # post-processing does not depend on the prompt: one set keeps the fixture small
                save(f"masks{k}.npy", postprocess(masks, S, hw, (H, W)))
        anns, amg_masks = automatic_masks(model, emb[0], pe, dense, S, hw, (H, W), AMG)
        np.save(os.path.join(OUT, "amg_masks.npy"), amg_masks)
        with open(os.path.join(OUT, "amg.json"), "w") as f:
            json.dump({"options": AMG, "masks": anns}, f, indent=1)
        print("AMG:", len(anns), "masks", [round(a["predicted_iou"], 3) for a in anns])
        if full:
            with open(os.path.join(OUT, "prompts.json"), "w") as f:
                json.dump({"image_hw": [H, W], "input_hw": list(hw), "prompts": prompts}, f, indent=1)
    print("wrote", OUT)


def main():
    global OUT
    base = OUT
    model, sd = make_model(CFG, 1234)
    os.makedirs(OUT, exist_ok=True)
    save_safetensors(os.path.join(OUT, "tiny_sam.safetensors"), sd)
    img8 = test_image()
    write_outputs(model, CFG, img8)

    # The pruned model (own seed) into OUT/pruned: the same image and prompt sets as above.
    OUT = os.path.join(base, "pruned")
    model, sd = make_model(CFG_PRUNED, 4321)
    os.makedirs(OUT, exist_ok=True)
    save_safetensors(os.path.join(OUT, "pruned_sam.safetensors"), sd)
    write_outputs(model, CFG_PRUNED, img8, full=False, lowres_sets=(1, 3))
    OUT = base


if __name__ == "__main__":
    main()
