#!/usr/bin/python3
"""Reference outputs for hgs's native CLIP (tests/clip). Run by hand, never by CI:

    /usr/bin/python3 tools/clip_reference/make_reference.py [OUT_DIR]   # default tests/data/clip

Needs Debian's python3-torch, python3-numpy and python3-regex. Builds two tiny random CLIP models with torch's
own layers (nn.MultiheadAttention, nn.LayerNorm, nn.GELU / QuickGELU, nn.Conv2d), saves their weights as
safetensors in both naming schemes and the outputs of the torch forward passes as .npy files:

  openclip_bf16/  open_clip naming, BF16 weights, GELU, with open_clip_config.json (heads)
  hf_f32/         Hugging Face CLIPModel naming, F32 weights, QuickGELU, with config.json (heads, hidden_act)
  tokens.json     CLIP tokenizer ids of tricky strings, from an independent Python implementation of the
                  "simple tokenizer" (regex module with \\p{L}/\\p{N}, html.unescape twice)
  tokens_fuzz.json  the same for 500 random strings over many Unicode blocks

Per model folder: text_ids.npy [T, 77] int32 and text_emb.npy [T, D] (normalised, full 77-token forward);
image.npy [S, S, 3] (a normalised input tensor), image_emb.npy [D] (normalised), dense.npy [g, g, D]
(MaskCLIP value path, not normalised); image_rect.npy [H2, W2, 3] and dense_rect.npy / image_rect_emb.npy
(positional embeddings bicubic-interpolated to a non-square grid); raw.npy [h, w, 3] in [0, 1] with
raw_pre.npy (CLIP preprocessing: antialiased bicubic resize of the shorter side, centre crop, mean/std) and
raw_emb.npy; raw_dense.npy (dense_features pipeline at input size 32, L2-normalised).
"""
import gzip
import html
import json
import math
import os
import struct
import sys
from collections import OrderedDict

import numpy as np
import regex
import torch
import torch.nn as nn
import torch.nn.functional as F

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
OUT = os.path.abspath(sys.argv[1]) if len(sys.argv) > 1 else os.path.join(ROOT, "tests", "data", "clip")
VOCAB_GZ = os.path.join(ROOT, "assets", "clip", "bpe_simple_vocab_16e6.txt.gz")
MEAN = (0.48145466, 0.4578275, 0.40821073)
STD = (0.26862954, 0.26130258, 0.27577711)

# ----------------------------------------------------------------------------------------------- tokenizer


def byte_table():
    bs = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), ord("ÿ") + 1))
    cs = list(bs)
    extra = 0
    for b in range(256):
        if b not in bs:
            bs.append(b)
            cs.append(256 + extra)
            extra += 1
    return dict(zip(bs, [chr(c) for c in cs]))


class Tokenizer:
    def __init__(self, path):
        lines = gzip.open(path).read().decode("utf-8").split("\n")
        merges = [tuple(l.split()) for l in lines[1:49152 - 256 - 2 + 1]]
        self.byte_enc = byte_table()
        base = list(self.byte_enc.values())
        vocab = base + [v + "</w>" for v in base] + ["".join(m) for m in merges]
        vocab += ["<|startoftext|>", "<|endoftext|>"]
        self.ids = {v: i for i, v in enumerate(vocab)}
        self.rank = {m: i for i, m in enumerate(merges)}
        self.pat = regex.compile(r"""<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+""",
                                 regex.IGNORECASE)

    @staticmethod
    def clean(text):
        # ftfy is not packaged by Debian: the subset hgs reproduces (quotes, ligatures, full-width forms) is
        # applied here by hand, then CLIP's html.unescape twice, whitespace collapse and lower().
        out = []
        for c in text:
            o = ord(c)
            if o == 0x02BC or 0x2018 <= o <= 0x201B:
                out.append("'")
            elif 0x201C <= o <= 0x201F:
                out.append('"')
            elif 0xFB00 <= o <= 0xFB06:
                out.append(["ff", "fi", "fl", "ffi", "ffl", "\u017ft", "st"][o - 0xFB00])
            elif 0xFF01 <= o <= 0xFF5E:
                out.append(chr(o - 0xFEE0))
            elif o == 0x3000:
                out.append(" ")
            else:
                out.append(c)
        text = html.unescape(html.unescape("".join(out))).strip()
        return regex.sub(r"\s+", " ", text).strip().lower()

    def bpe(self, piece):
        if piece in ("<|startoftext|>", "<|endoftext|>"):
            return [piece]
        word = list(piece[:-1]) + [piece[-1] + "</w>"]
        while len(word) > 1:
            pairs = [(word[i], word[i + 1]) for i in range(len(word) - 1)]
            best = min(pairs, key=lambda p: self.rank.get(p, math.inf))
            if best not in self.rank:
                break
            new, i = [], 0
            while i < len(word):
                if i + 1 < len(word) and word[i] == best[0] and word[i + 1] == best[1]:
                    new.append(word[i] + word[i + 1])
                    i += 2
                else:
                    new.append(word[i])
                    i += 1
            word = new
        return word

    def encode(self, text):
        ids = []
        for piece in self.pat.findall(self.clean(text)):
            if piece not in ("<|startoftext|>", "<|endoftext|>"):
                piece = "".join(self.byte_enc[b] for b in piece.encode("utf-8"))
            ids += [self.ids[s] for s in self.bpe(piece)]
        return ids

    def tokenize(self, text, context=77):
        ids = [49406] + self.encode(text) + [49407]
        if len(ids) > context:
            ids = ids[:context]
            ids[-1] = 49407
        return ids


TOKEN_CASES = [
    "a photo of a cat",
    "",
    "   ",
    "Hello, World!!! How's it going?",
    "I'm sure they'll say we've done what's right, didn't you'd?",
    "3.14159 and 2024-11-22, 100% of $42",
    "Café naïve façade Über straße",
    "日本語のテキスト 中文 한국어",
    "Привет мир, ΑΒΓ αβγ",
    "emoji 🐱🐶 and ★ symbols ©",
    "&amp; &lt;b&gt; &quot;quoted&quot; &#39;single&#39; &#x263A; &amp;amp; &copy &nbsp;x",
    "tabs\tand\nnewlines   and\u00a0nbsp",
    "“curly” ‘quotes’ and ﬁne ligatures, ＦＵＬＬ　ｗｉｄｔｈ",
    "<|startoftext|>already special<|endoftext|> tokens",
    "UPPER lower MiXeD",
    "a " * 100,
    "pneumonoultramicroscopicsilicovolcanoconiosis antidisestablishmentarianism",
    "İSTANBUL ΟΔΥΣΣΕΥΣ ΣΑΣ. Σ",                      # Python's full lower case: U+0130, final sigma
    "\x1cfile\x1dsep\x1f and NEL\x85here \x1e",    # str.strip vs the regex module's \s
    "a\u0345b ᾳ \u0345",                              # U+0345 matches none of the split alternatives
    "हिन्दी ไทย العربية",                                 # combining marks split letter runs
]


def fuzz_cases(n, seed):
    """Random strings over many Unicode blocks (letters, marks, digits, spaces, controls, emoji)."""
    import random
    rng = random.Random(seed)
    ranges = [(0x20, 0x7E), (0xA0, 0x17F), (0x300, 0x36F), (0x370, 0x3FF), (0x400, 0x4FF), (0x590, 0x6FF),
              (0x900, 0x97F), (0xE00, 0xE7F), (0x1E00, 0x1EFF), (0x2000, 0x206F), (0x2100, 0x214F), (0x3000, 0x30FF),
              (0x4E00, 0x4E80), (0xAC00, 0xAC80), (0xFF00, 0xFFEF), (0x1F300, 0x1F6FF), (0x1C, 0x1F), (0x85, 0x85),
              (0x9, 0xD)]
    return ["".join(chr(rng.randint(*rng.choice(ranges))) for _ in range(rng.randint(0, 25))) for _ in range(n)]

# --------------------------------------------------------------------------------------------------- model


class QuickGELU(nn.Module):
    def forward(self, x):
        return x * torch.sigmoid(1.702 * x)


class ResBlock(nn.Module):
    def __init__(self, width, heads, act):
        super().__init__()
        self.ln_1 = nn.LayerNorm(width)
        self.attn = nn.MultiheadAttention(width, heads)
        self.ln_2 = nn.LayerNorm(width)
        self.mlp = nn.Sequential(OrderedDict(c_fc=nn.Linear(width, 4 * width), gelu=act(), c_proj=nn.Linear(4 * width, width)))

    def forward(self, x, mask=None):  # x [L, N, width]
        y = self.ln_1(x)
        x = x + self.attn(y, y, y, need_weights=False, attn_mask=mask)[0]
        return x + self.mlp(self.ln_2(x))


class Transformer(nn.Module):
    def __init__(self, width, layers, heads, act):
        super().__init__()
        self.resblocks = nn.ModuleList([ResBlock(width, heads, act) for _ in range(layers)])


class Visual(nn.Module):
    def __init__(self, width, layers, heads, patch, image, dim, act):
        super().__init__()
        self.patch, self.grid = patch, image // patch
        self.conv1 = nn.Conv2d(3, width, patch, patch, bias=False)
        self.class_embedding = nn.Parameter(torch.randn(width) * width ** -0.5)
        self.positional_embedding = nn.Parameter(torch.randn(self.grid ** 2 + 1, width) * 0.5)
        self.ln_pre = nn.LayerNorm(width)
        self.transformer = Transformer(width, layers, heads, act)
        self.ln_post = nn.LayerNorm(width)
        self.proj = nn.Parameter(torch.randn(width, dim) * width ** -0.5)

    def tokens(self, x):  # x [1, 3, H, W] -> [n + 1, 1, width]
        x = self.conv1(x)
        gh, gw = x.shape[2], x.shape[3]
        x = x.flatten(2).permute(0, 2, 1)
        pos = self.positional_embedding
        if (gh, gw) != (self.grid, self.grid):  # bicubic, align_corners=False (Hugging Face's interpolate_pos_encoding)
            g = pos[1:].reshape(1, self.grid, self.grid, -1).permute(0, 3, 1, 2)
            g = F.interpolate(g, size=(gh, gw), mode="bicubic", align_corners=False)
            pos = torch.cat([pos[:1], g.permute(0, 2, 3, 1).reshape(gh * gw, -1)])
        x = torch.cat([self.class_embedding.reshape(1, 1, -1), x], dim=1) + pos
        return self.ln_pre(x).permute(1, 0, 2), gh, gw

    def forward(self, x):
        x, _, _ = self.tokens(x)
        for b in self.transformer.resblocks:
            x = b(x)
        return self.ln_post(x[0]) @ self.proj  # [1, D]

    def dense(self, x):  # MaskCLIP: last block's value path for the patch tokens
        x, gh, gw = self.tokens(x)
        blocks = self.transformer.resblocks
        for b in blocks[:-1]:
            x = b(x)
        last = blocks[-1]
        w = x.shape[-1]
        y = last.ln_1(x[1:, 0])
        v = F.linear(y, last.attn.in_proj_weight[2 * w:], last.attn.in_proj_bias[2 * w:])
        v = last.attn.out_proj(v)
        return (self.ln_post(v) @ self.proj).reshape(gh, gw, -1)


class CLIP(nn.Module):
    def __init__(self, dim, vision, text, act):
        super().__init__()
        self.visual = Visual(*vision, dim=dim, act=act)
        width, layers, heads, vocab, ctx = text
        self.token_embedding = nn.Embedding(vocab, width)
        self.positional_embedding = nn.Parameter(torch.randn(ctx, width) * 0.1)
        self.transformer = Transformer(width, layers, heads, act)
        self.ln_final = nn.LayerNorm(width)
        self.text_projection = nn.Parameter(torch.randn(width, dim) * width ** -0.5)
        self.logit_scale = nn.Parameter(torch.tensor(math.log(1 / 0.07)))
        self.register_buffer("attn_mask", torch.full((ctx, ctx), float("-inf")).triu(1), persistent=False)

    def encode_text(self, ids):  # ids [T, ctx]
        x = (self.token_embedding(ids) + self.positional_embedding).permute(1, 0, 2)
        for b in self.transformer.resblocks:
            x = b(x, self.attn_mask)
        x = self.ln_final(x.permute(1, 0, 2))
        return x[torch.arange(ids.shape[0]), ids.argmax(-1)] @ self.text_projection


def randomize(model):
    """Non-trivial LayerNorm and bias values so that every parameter matters."""
    for name, p in model.named_parameters():
        if name.endswith("ln_1.weight") or name.endswith("ln_2.weight") or "ln_" in name and name.endswith(".weight"):
            p.data = 1 + 0.2 * torch.randn_like(p)
        elif name.endswith("bias"):
            p.data = 0.1 * torch.randn_like(p)


def round_params(model, dtype):
    for p in model.parameters():
        p.data = p.data.to(dtype).to(torch.float32)


# ------------------------------------------------------------------------------------------------- files

def write_safetensors(path, tensors, dtype):
    """tensors: OrderedDict name -> float32 tensor; dtype one of F32, F16, BF16."""
    tdt = {"F32": torch.float32, "F16": torch.float16, "BF16": torch.bfloat16}[dtype]
    header, blobs, off = {}, [], 0
    for name, t in tensors.items():
        t = t.detach().contiguous().to(tdt)
        raw = t.view(torch.int16).numpy().tobytes() if tdt == torch.bfloat16 else t.numpy().tobytes()
        header[name] = {"dtype": dtype, "shape": list(t.shape), "data_offsets": [off, off + len(raw)]}
        blobs.append(raw)
        off += len(raw)
    header["__metadata__"] = {"format": "pt", "generator": "hgs tools/clip_reference/make_reference.py"}
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * ((8 - (8 + len(h)) % 8) % 8)
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(h)))
        f.write(h)
        for b in blobs:
            f.write(b)


def openclip_state(model):
    return OrderedDict((k, v) for k, v in model.state_dict().items())


def hf_state(model):
    """The same weights under Hugging Face CLIPModel names (q/k/v split, Linear projections transposed)."""
    sd, out = model.state_dict(), OrderedDict()

    def tower(src, dst, n_layers, width):
        for i in range(n_layers):
            s, d = f"{src}.{i}.", f"{dst}.{i}."
            for a, b in (("ln_1", "layer_norm1"), ("ln_2", "layer_norm2")):
                out[d + b + ".weight"], out[d + b + ".bias"] = sd[s + a + ".weight"], sd[s + a + ".bias"]
            w, bias = sd[s + "attn.in_proj_weight"], sd[s + "attn.in_proj_bias"]
            for j, n in enumerate(("q_proj", "k_proj", "v_proj")):
                out[d + f"self_attn.{n}.weight"] = w[j * width:(j + 1) * width]
                out[d + f"self_attn.{n}.bias"] = bias[j * width:(j + 1) * width]
            out[d + "self_attn.out_proj.weight"] = sd[s + "attn.out_proj.weight"]
            out[d + "self_attn.out_proj.bias"] = sd[s + "attn.out_proj.bias"]
            for a, b in (("mlp.c_fc", "mlp.fc1"), ("mlp.c_proj", "mlp.fc2")):
                out[d + b + ".weight"], out[d + b + ".bias"] = sd[s + a + ".weight"], sd[s + a + ".bias"]

    vw = sd["visual.conv1.weight"].shape[0]
    tw = sd["token_embedding.weight"].shape[1]
    out["text_model.embeddings.token_embedding.weight"] = sd["token_embedding.weight"]
    out["text_model.embeddings.position_embedding.weight"] = sd["positional_embedding"]
    tower("transformer.resblocks", "text_model.encoder.layers", len(model.transformer.resblocks), tw)
    out["text_model.final_layer_norm.weight"], out["text_model.final_layer_norm.bias"] = sd["ln_final.weight"], sd["ln_final.bias"]
    out["vision_model.embeddings.class_embedding"] = sd["visual.class_embedding"]
    out["vision_model.embeddings.patch_embedding.weight"] = sd["visual.conv1.weight"]
    out["vision_model.embeddings.position_embedding.weight"] = sd["visual.positional_embedding"]
    out["vision_model.pre_layrnorm.weight"], out["vision_model.pre_layrnorm.bias"] = sd["visual.ln_pre.weight"], sd["visual.ln_pre.bias"]
    tower("visual.transformer.resblocks", "vision_model.encoder.layers", len(model.visual.transformer.resblocks), vw)
    out["vision_model.post_layernorm.weight"], out["vision_model.post_layernorm.bias"] = sd["visual.ln_post.weight"], sd["visual.ln_post.bias"]
    out["visual_projection.weight"] = sd["visual.proj"].t()
    out["text_projection.weight"] = sd["text_projection"].t()
    out["logit_scale"] = sd["logit_scale"]
    return out


def to_chw(x_hwc):
    return torch.from_numpy(x_hwc).permute(2, 0, 1).unsqueeze(0)


def normalize_chw(x):
    return (x - torch.tensor(MEAN).view(1, 3, 1, 1)) / torch.tensor(STD).view(1, 3, 1, 1)


def clip_preprocess(raw, size):  # raw [h, w, 3] numpy in [0, 1]
    h, w = raw.shape[:2]
    if w <= h:
        ow, oh = size, int(size * h / w)
    else:
        oh, ow = size, int(size * w / h)
    # float64: torch's float32 antialiased resampling is itself only accurate to ~5e-6
    x = F.interpolate(to_chw(raw).double(), size=(oh, ow), mode="bicubic", align_corners=False, antialias=True).float()
    top, left = int(round((oh - size) / 2.0)), int(round((ow - size) / 2.0))
    return normalize_chw(x[:, :, top:top + size, left:left + size])


def save(folder, name, arr):
    np.save(os.path.join(folder, name + ".npy"), np.ascontiguousarray(arr))


def make_model(folder, seed, naming, dtype, act, text_width, text_heads, phrases, tok):
    torch.manual_seed(seed)
    dim, vwidth, vheads, patch, image = 32, 64, 4, 16, 48
    model = CLIP(dim, (vwidth, 2, vheads, patch, image), (text_width, 2, text_heads, 49408, 77), act)
    randomize(model)
    round_params(model, {"F32": torch.float32, "F16": torch.float16, "BF16": torch.bfloat16}[dtype])
    model.eval()
    os.makedirs(folder, exist_ok=True)
    if naming == "open_clip":
        write_safetensors(os.path.join(folder, "model.safetensors"), openclip_state(model), dtype)
        cfg = {"model_cfg": {"embed_dim": dim, "quick_gelu": act is QuickGELU,
                             "vision_cfg": {"width": vwidth, "layers": 2, "patch_size": patch, "image_size": image,
                                            "head_width": vwidth // vheads},
                             "text_cfg": {"width": text_width, "heads": text_heads, "layers": 2, "context_length": 77,
                                          "vocab_size": 49408}}}
        json.dump(cfg, open(os.path.join(folder, "open_clip_config.json"), "w"), indent=1)
    else:
        write_safetensors(os.path.join(folder, "model.safetensors"), hf_state(model), dtype)
        hact = "quick_gelu" if act is QuickGELU else "gelu"
        cfg = {"architectures": ["CLIPModel"], "projection_dim": dim,
               "text_config": {"hidden_size": text_width, "num_attention_heads": text_heads, "num_hidden_layers": 2,
                               "hidden_act": hact},
               "vision_config": {"hidden_size": vwidth, "num_attention_heads": vheads, "num_hidden_layers": 2,
                                 "patch_size": patch, "image_size": image, "hidden_act": hact}}
        json.dump(cfg, open(os.path.join(folder, "config.json"), "w"), indent=1)

    g = torch.Generator().manual_seed(seed + 1)
    with torch.no_grad():
        ids = torch.tensor([tok.tokenize(p) + [0] * (77 - len(tok.tokenize(p))) for p in phrases], dtype=torch.long)
        t = model.encode_text(ids)
        save(folder, "text_ids", ids.numpy().astype(np.int32))
        save(folder, "text_emb", F.normalize(t, dim=-1).numpy())

        img = torch.randn(1, 3, image, image, generator=g)
        save(folder, "image", img[0].permute(1, 2, 0).numpy())
        save(folder, "image_emb", F.normalize(model.visual(img), dim=-1)[0].numpy())
        save(folder, "dense", model.visual.dense(img).numpy())

        rect = torch.randn(1, 3, 64, 32, generator=g)  # grid 4 x 2 from a native 3 x 3
        save(folder, "image_rect", rect[0].permute(1, 2, 0).numpy())
        save(folder, "image_rect_emb", F.normalize(model.visual(rect), dim=-1)[0].numpy())
        save(folder, "dense_rect", model.visual.dense(rect).numpy())

        raw = torch.rand(37, 53, 3, generator=g).numpy()
        save(folder, "raw", raw)
        pre = clip_preprocess(raw, image)
        save(folder, "raw_pre", pre[0].permute(1, 2, 0).numpy())
        save(folder, "raw_emb", F.normalize(model.visual(pre), dim=-1)[0].numpy())
        big = torch.rand(70, 90, 3, generator=g).numpy()
        save(folder, "raw_big", big)
        save(folder, "raw_big_pre", clip_preprocess(big, image)[0].permute(1, 2, 0).numpy())
        # dense_features at input size 32: 37 x 53 -> grid round(37*32/37/16)=2 x round(53*32/37/16)=3 -> 32 x 48
        x = F.interpolate(to_chw(raw).double(), size=(32, 48), mode="bicubic", align_corners=False, antialias=True).float()
        save(folder, "raw_dense", F.normalize(model.visual.dense(normalize_chw(x)), dim=-1).numpy())


def main():
    tok = Tokenizer(VOCAB_GZ)
    os.makedirs(OUT, exist_ok=True)
    cases = [{"text": s, "ids": tok.tokenize(s)} for s in TOKEN_CASES]
    json.dump(cases, open(os.path.join(OUT, "tokens.json"), "w", encoding="utf-8"), ensure_ascii=False, indent=1)
    fuzz = [{"text": s, "ids": tok.tokenize(s)} for s in fuzz_cases(500, 7)]
    json.dump(fuzz, open(os.path.join(OUT, "tokens_fuzz.json"), "w", encoding="utf-8"), ensure_ascii=False)
    phrases = ["a photo of a cat", "chair", "the red mug on the wooden table, seen from above", "",
               "a " * 100, "Café & “tea”"]
    json.dump(phrases, open(os.path.join(OUT, "phrases.json"), "w", encoding="utf-8"), ensure_ascii=False)
    make_model(os.path.join(OUT, "openclip_bf16"), 1, "open_clip", "BF16", nn.GELU, 16, 2, phrases, tok)
    make_model(os.path.join(OUT, "hf_f32"), 2, "hf", "F32", QuickGELU, 8, 2, phrases, tok)
    total = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(OUT) for f in fs)
    print(f"wrote {OUT} ({total / 1e6:.2f} MB)")


if __name__ == "__main__":
    main()
