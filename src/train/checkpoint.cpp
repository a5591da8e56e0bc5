// Trainer checkpoints. Layout: the 8 bytes "HGSCKPT1", a little-endian uint64 header length, a JSON header
// {config, iteration, extent, n, sh_degree, extras [{name, dim, f16}], adam {params [{name, dim, lr, bf16,
// scope, step, eps}]}, rng (text state of std::mt19937_64), order, order_pos, method, method_config (optional),
// arrays [{name, count}]}, then the arrays' float32 values back to back in header order: model fields
// (half-precision extra groups widened, exact), for every registered optimiser parameter its values when they
// do not live in the model ("param/<name>", e.g. the hybrid method's view logits) and its Adam m and v
// (bfloat16 moments widened, exact), densification statistics, then the method's non-parameter state
// ("method/<name>", e.g. the hybrid method's observation table). No per-method code: every parameter the method
// registered is saved and restored by name. Read and written in streams (no whole-file buffer).
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"
#include "core/half.h"
#include "train/trainer.h"

namespace hgs::train {
namespace {
constexpr char kMagic[8] = {'H', 'G', 'S', 'C', 'K', 'P', 'T', '1'};
constexpr size_t kChunk = size_t(1) << 20;  // values converted per chunk for bfloat16 arrays

struct FileCloser {
  void operator()(FILE* f) const { std::fclose(f); }
};
}  // namespace

void Trainer::save_checkpoint(const std::filesystem::path& path) const {
  using nlohmann::json;
  auto& m = const_cast<GaussianModel&>(model_);
  // Arrays to write: float32 data, or bfloat16 moments widened chunk by chunk while writing (no full copy).
  struct Out {
    std::string name;
    size_t count;
    const float* f32;
    const uint16_t* h16;  // 16-bit storage widened while writing
    bool fp16;            // h16 is IEEE half (else bfloat16)
  };
  std::vector<Out> arrays;
  auto add = [&](const std::string& name, const std::vector<float>* v) {
    arrays.push_back({name, v->size(), v->data(), nullptr, false});
  };
  for (auto& f : m.fields()) add("model/" + f.name, f.data);
  for (auto& e : m.extras)
    if (e.f16) arrays.push_back({"model/" + e.name, e.half.size(), nullptr, e.half.data(), true});
  for (auto& p : adam_.params) {
    if (p.scope == ParamScope::Array) {
      if (!p.values || !p.values().f32) fail("checkpoint: array parameter '{}' has no float32 values to save", p.name);
      add("param/" + p.name, p.values().f32);
    }
    if (p.bf16) {
      arrays.push_back({"adam_m/" + p.name, p.m16.size(), nullptr, p.m16.data(), false});
      arrays.push_back({"adam_v/" + p.name, p.v16.size(), nullptr, p.v16.data(), false});
    } else {
      add("adam_m/" + p.name, &p.m);
      add("adam_v/" + p.name, &p.v);
    }
  }
  std::vector<float> counts(stats_.count.begin(), stats_.count.end());
  add("stats/grad_accum", &stats_.grad_accum);
  add("stats/count", &counts);
  add("stats/max_radius", &stats_.max_radius);
  const auto method = method_->state();  // copies, alive until the file is written
  for (auto& [name, a] : method) add("method/" + name, &a);
  json h;
  h["config"] = cfg_.to_json();
  h["method"] = method_->name();
  if (nlohmann::json mc = method_->config(); !mc.is_null()) h["method_config"] = mc;
  h["iteration"] = it_;
  h["extent"] = extent_;
  h["n"] = model_.n;
  h["sh_degree"] = model_.sh_degree;
  h["num_views"] = views_.size();
  h["extras"] = json::array();
  for (auto& e : model_.extras) h["extras"].push_back({{"name", e.name}, {"dim", e.dim}, {"f16", e.f16}});
  h["adam"]["params"] = json::array();
  for (auto& p : adam_.params)
    h["adam"]["params"].push_back({{"name", p.name},
                                   {"dim", p.dim},
                                   {"lr", p.lr},
                                   {"bf16", p.bf16},
                                   {"step", p.step},
                                   {"eps", p.eps},
                                   {"scope", p.scope == ParamScope::Array ? "array" : "gaussian"}});
  std::ostringstream rs;
  rs << rng_;
  h["rng"] = rs.str();
  h["order"] = order_;
  h["order_pos"] = order_pos_;
  h["arrays"] = json::array();
  for (auto& a : arrays) h["arrays"].push_back({{"name", a.name}, {"count", a.count}});
  std::string hs = h.dump();
  atomic_write(path, [&](const std::filesystem::path& tmp) {
    FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) fail("{}: cannot open for writing", path.string());
    uint64_t len = hs.size();
    bool ok = std::fwrite(kMagic, 1, 8, f) == 8 && std::fwrite(&len, 8, 1, f) == 1 &&
              std::fwrite(hs.data(), 1, hs.size(), f) == hs.size();
    std::vector<float> chunk;
    for (auto& a : arrays) {
      if (a.f32) {
        ok = ok && std::fwrite(a.f32, 4, a.count, f) == a.count;
        continue;
      }
      for (size_t i = 0; ok && i < a.count; i += kChunk) {
        const size_t c = std::min(kChunk, a.count - i);
        chunk.resize(c);
        for (size_t k = 0; k < c; ++k) chunk[k] = a.fp16 ? half_to_float(a.h16[i + k]) : bf16_to_float(a.h16[i + k]);
        ok = std::fwrite(chunk.data(), 4, c, f) == c;
      }
    }
    int err = ok ? 0 : errno;  // of the failed write (e.g. ENOSPC, EFBIG)
    if (std::fclose(f) != 0 && ok) ok = false, err = errno;
    if (!ok) fail("{}: write failed ({})", path.string(), err ? std::strerror(err) : "disk full?");
  });
}

namespace {

using nlohmann::json;

// The JSON header after the magic bytes; `file_size` bounds every size read from the file.
json read_header(FILE* fp, const std::string& where, uint64_t file_size) {
  char magic[8];
  uint64_t len = 0;
  if (std::fread(magic, 1, 8, fp) != 8 || std::memcmp(magic, kMagic, 8) != 0) fail("{}: not an hgs checkpoint", where);
  if (std::fread(&len, 8, 1, fp) != 1 || len > file_size - std::min<uint64_t>(file_size, 16))
    fail("{}: truncated checkpoint header", where);
  std::string hs(len, '\0');
  if (std::fread(hs.data(), 1, len, fp) != len) fail("{}: truncated checkpoint header", where);
  try {
    return json::parse(hs);
  } catch (const std::exception& e) {
    fail("{}: corrupt checkpoint header", where);
  }
}

// The model of the checkpoint, sized by its header (values read later).
GaussianModel header_model(const json& h) {
  GaussianModel m;
  m.sh_degree = h.at("sh_degree").get<int>();
  m.resize(h.at("n").get<int>());
  for (auto& e : h.at("extras"))
    m.add_extra(e.at("name").get<std::string>(), e.at("dim").get<int>(), 0.f, e.value("f16", false));
  return m;
}

// The optimiser's parameters, read into copies of the registered ones (same names, same kind) so that their value
// bindings stay; per-Gaussian ones are sized by the checkpoint's Gaussian count `n`. `values` receives an empty
// buffer "param/<name>" for every array parameter.
std::deque<AdamParam> header_params(const json& h, const std::string& where, const std::deque<AdamParam>& registered,
                                    int n, std::map<std::string, std::vector<float>>& values) {
  const json& hp = h.at("adam").at("params");
  if (hp.size() != registered.size())
    fail("{}: the checkpoint holds {} optimiser parameters, this trainer has {} (written by another hgs version?)",
         where, hp.size(), registered.size());
  std::deque<AdamParam> a;
  for (size_t i = 0; i < hp.size(); ++i) {
    const json& p = hp[i];
    const AdamParam& cur = registered[i];
    const std::string name = p.at("name").get<std::string>();
    const bool array = p.value("scope", std::string("gaussian")) == "array";
    if (name != cur.name || p.at("dim").get<int>() != cur.dim || array != (cur.scope == ParamScope::Array) ||
        p.value("bf16", false) != cur.bf16)
      fail("{}: optimiser parameter {} is '{}' [{}], this trainer's is '{}' [{}]", where, i, name,
           p.at("dim").get<int>(), cur.name, cur.dim);
    AdamParam ap;
    ap.name = cur.name;
    ap.dim = cur.dim;
    ap.scope = cur.scope;
    ap.bf16 = cur.bf16;
    ap.values = cur.values;
    ap.step = p.contains("step") ? p.at("step").get<long>() : h.at("adam").at("step").get<long>();
    ap.eps = p.value("eps", cur.eps);
    ap.lr = p.at("lr").get<std::vector<float>>();
    if (int(ap.lr.size()) != ap.dim)
      fail("{}: parameter '{}' has {} learning rates for {} columns", where, ap.name, ap.lr.size(), ap.dim);
    const size_t rows = array ? cur.rows() : size_t(n);
    if (ap.bf16) {
      ap.m16.resize(rows * ap.dim);
      ap.v16.resize(rows * ap.dim);
    } else {
      ap.m.resize(rows * ap.dim);
      ap.v.resize(rows * ap.dim);
    }
    if (array) values["param/" + ap.name].resize(rows * ap.dim);
    a.push_back(std::move(ap));
  }
  return a;
}

// Where each named array of the file goes: float32 buffers (sized, except the method's state, which the file
// sizes), and 16-bit ones stored as float32 in the file (half-precision extras, bfloat16 moments): {array, is fp16}.
struct ArrayTargets {
  std::map<std::string, std::vector<float>*> f32;
  std::map<std::string, std::pair<std::vector<uint16_t>*, bool>> f16;
};

// Reads the arrays the header lists into `t`; every target must be filled exactly once.
void read_arrays(FILE* fp, const json& h, const std::string& where, uint64_t file_size, const ArrayTargets& t) {
  size_t seen = 0;
  std::vector<float> chunk;
  for (auto& ar : h.at("arrays")) {
    std::string name = ar.at("name").get<std::string>();
    size_t count = ar.at("count").get<size_t>();
    auto it = t.f32.find(name);
    auto it16 = t.f16.find(name);
    if (it == t.f32.end() && it16 == t.f16.end()) fail("{}: unexpected array '{}'", where, name);
    if (it != t.f32.end()) {
      if (name.rfind("method/", 0) == 0) {  // sizes checked by method_state_loaded; here only against the file
        const long pos = std::ftell(fp);
        if (pos < 0 || count > (file_size - uint64_t(pos)) / 4)
          fail("{}: truncated checkpoint (array '{}')", where, name);
        it->second->resize(count);
      }
      if (it->second->size() != count)
        fail("{}: array '{}' has {} values, expected {}", where, name, count, it->second->size());
      if (std::fread(it->second->data(), 4, count, fp) != count)
        fail("{}: truncated checkpoint (array '{}')", where, name);
    } else {
      std::vector<uint16_t>& d = *it16->second.first;
      const bool fp16 = it16->second.second;
      if (d.size() != count) fail("{}: array '{}' has {} values, expected {}", where, name, count, d.size());
      for (size_t i = 0; i < count; i += kChunk) {
        const size_t c = std::min(kChunk, count - i);
        chunk.resize(c);
        if (std::fread(chunk.data(), 4, c, fp) != c) fail("{}: truncated checkpoint (array '{}')", where, name);
        for (size_t k = 0; k < c; ++k)  // exact: the values were written from these 16-bit formats
          d[i + k] = fp16 ? float_to_half(chunk[k]) : float_to_bf16(chunk[k]);
      }
    }
    ++seen;
  }
  if (seen != t.f32.size() + t.f16.size())
    fail("{}: checkpoint holds {} arrays, expected {}", where, seen, t.f32.size() + t.f16.size());
}

// The densification counts, written from ints: anything else is corruption (and casting it undefined).
void take_counts(const std::vector<float>& counts, const std::string& where, DensifyStats& st) {
  for (size_t i = 0; i < counts.size(); ++i) {
    const float c = counts[i];
    if (!(c >= 0 && c <= float(1 << 24) && c == std::floor(c)))
      fail("{}: corrupt densification statistics (count {} of Gaussian {})", where, c, i);
    st.count[i] = int(c);
  }
}

}  // namespace

void Trainer::load_checkpoint(const std::filesystem::path& path) {
  const std::string where = path.string();
  // Streamed from the file (a 300k x 512 checkpoint is ~2 GB: never held in memory as a whole).
  std::unique_ptr<FILE, FileCloser> file(std::fopen(path.c_str(), "rb"));
  if (!file) fail("{}: cannot open checkpoint", where);
  FILE* fp = file.get();
  // Sizes from the file are checked against the file's own size before anything is allocated by them.
  std::error_code size_ec;
  const uint64_t file_size = std::filesystem::file_size(path, size_ec);
  if (size_ec) fail("{}: cannot read checkpoint size ({})", where, size_ec.message());
  const json h = read_header(fp, where, file_size);
  try {
    if (h.at("num_views").get<size_t>() != views_.size())
      fail("{}: checkpoint was trained on {} views, this scene has {}", where, h.at("num_views").get<size_t>(),
           views_.size());
    TrainConfig c = TrainConfig::from_json(h.at("config"), where);
    c.iters = cfg_.iters;
    c.save_every = cfg_.save_every;
    c.batch = cfg_.batch;        // a run may resume with another batch or number of ranks
    c.batch_lr = cfg_.batch_lr;  // and its rule (the optimiser was set up with it)
    GaussianModel m = header_model(h);
    // A checkpoint without a method name is hybrid when it holds a method configuration (files written before
    // the method registry), else rgb.
    const std::string trained = h.value("method", std::string(h.contains("method_config") ? "hybrid" : "rgb"));
    if (trained != method_->name())
      fail("{}: the checkpoint was trained with the {} method, not {}", where, trained, method_->name());
    std::map<std::string, std::vector<float>> values;  // param/<name> of array parameters
    std::deque<AdamParam> a = header_params(h, where, adam_.params, m.n, values);
    DensifyStats st;
    st.reset(m.n);
    std::vector<float> counts(m.n);
    ArrayTargets t;
    for (auto& f : m.fields()) t.f32["model/" + f.name] = f.data;
    for (auto& e : m.extras)
      if (e.f16) t.f16["model/" + e.name] = {&e.half, true};
    for (auto& [name, v] : values) t.f32[name] = &v;
    for (auto& p : a) {
      if (p.bf16) {
        t.f16["adam_m/" + p.name] = {&p.m16, false};
        t.f16["adam_v/" + p.name] = {&p.v16, false};
      } else {
        t.f32["adam_m/" + p.name] = &p.m;
        t.f32["adam_v/" + p.name] = &p.v;
      }
    }
    // The method's own state is read into copies (sized by the file) and handed to method_state_loaded.
    std::map<std::string, std::vector<float>> method;
    for (auto& [name, arr] : method_->state())
      t.f32["method/" + name] = &(method[name] = std::vector<float>(arr.size()));
    t.f32["stats/grad_accum"] = &st.grad_accum;
    t.f32["stats/count"] = &counts;
    t.f32["stats/max_radius"] = &st.max_radius;
    read_arrays(fp, h, where, file_size, t);
    take_counts(counts, where, st);
    std::istringstream rs(h.at("rng").get<std::string>());
    std::mt19937_64 rng;
    rs >> rng;
    if (rs.fail()) fail("{}: corrupt random-generator state", where);
    std::vector<int> order = h.at("order").get<std::vector<int>>();
    for (int o : order)
      if (o < 0 || o >= int(views_.size())) fail("{}: corrupt view order", where);
    m.validate(where);
    // Everything parsed and checked: commit (the method checks its own state before it takes it).
    method_->state_loaded(where, h.value("method_config", json(nullptr)), m.n, method);
    cfg_ = c;
    for (TrainView& v : views_) v.cam.near_plane = cfg_.near_plane;  // the run continues as it was trained
    model_ = std::move(m);
    for (size_t i = 0; i < a.size(); ++i) {
      AdamParam& p = adam_.params[i];
      p = std::move(a[i]);
      if (p.scope == ParamScope::Array) *p.values().f32 = std::move(values["param/" + p.name]);
    }
    stats_ = std::move(st);
    rng_ = rng;
    order_ = std::move(order);
    order_pos_ = h.at("order_pos").get<size_t>();
    it_ = h.at("iteration").get<int>();
    extent_ = h.at("extent").get<float>();
  } catch (const json::exception& e) {
    fail("{}: malformed checkpoint header ({})", where, e.what());
  }
}

}  // namespace hgs::train
