// Trainer checkpoints. Layout: the 8 bytes "HGSCKPT1", a little-endian uint64 header length, a JSON header
// {config, iteration, extent, n, sh_degree, extras [{name, dim}], adam {step, params [{name, dim, lr, bf16}]},
// rng (text state of std::mt19937_64), order, order_pos, arrays [{name, count}]}, then the arrays' float32
// values back to back in header order: model fields, Adam m and v per parameter (bfloat16 moments are widened
// to float32, which is exact), densification statistics, then the method's own state ("method/<name>", e.g.
// the hybrid method's view logits).
#include <cstring>
#include <deque>
#include <sstream>

#include "core/error.h"
#include "core/half.h"
#include "core/fs.h"
#include "train/trainer.h"

namespace hgs::train {
namespace {
constexpr char kMagic[8] = {'H', 'G', 'S', 'C', 'K', 'P', 'T', '1'};
}

void Trainer::save_checkpoint(const std::filesystem::path& path) const {
  using nlohmann::json;
  auto& m = const_cast<GaussianModel&>(model_);
  std::vector<std::pair<std::string, const std::vector<float>*>> arrays;
  std::deque<std::vector<float>> widened;  // float32 copies of bfloat16 moments
  auto widen = [&](const std::vector<uint16_t>& b) {
    widened.emplace_back(b.size());
    for (size_t i = 0; i < b.size(); ++i) widened.back()[i] = bf16_to_float(b[i]);
    return &widened.back();
  };
  for (auto& f : m.fields()) arrays.push_back({"model/" + f.name, f.data});
  for (auto& p : adam_.params) {
    arrays.push_back({"adam_m/" + p.name, p.bf16 ? widen(p.m16) : &p.m});
    arrays.push_back({"adam_v/" + p.name, p.bf16 ? widen(p.v16) : &p.v});
  }
  std::vector<float> counts(stats_.count.begin(), stats_.count.end());
  arrays.push_back({"stats/grad_accum", &stats_.grad_accum});
  arrays.push_back({"stats/count", &counts});
  arrays.push_back({"stats/max_radius", &stats_.max_radius});
  for (auto& [name, a] : const_cast<Trainer*>(this)->method_state()) arrays.push_back({"method/" + name, a});
  json h;
  h["config"] = cfg_.to_json();
  h["iteration"] = it_;
  h["extent"] = extent_;
  h["n"] = model_.n;
  h["sh_degree"] = model_.sh_degree;
  h["num_views"] = views_.size();
  h["extras"] = json::array();
  for (auto& e : model_.extras) h["extras"].push_back({{"name", e.name}, {"dim", e.dim}});
  h["adam"]["step"] = adam_.step_count;
  h["adam"]["params"] = json::array();
  for (auto& p : adam_.params) h["adam"]["params"].push_back({{"name", p.name}, {"dim", p.dim}, {"lr", p.lr}, {"bf16", p.bf16}});
  std::ostringstream rs;
  rs << rng_;
  h["rng"] = rs.str();
  h["order"] = order_;
  h["order_pos"] = order_pos_;
  h["arrays"] = json::array();
  for (auto& [name, a] : arrays) h["arrays"].push_back({{"name", name}, {"count", a->size()}});
  std::string hs = h.dump();
  atomic_write(path, [&](const std::filesystem::path& tmp) {
    FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) fail("{}: cannot open for writing", path.string());
    uint64_t len = hs.size();
    bool ok = std::fwrite(kMagic, 1, 8, f) == 8 && std::fwrite(&len, 8, 1, f) == 1 &&
              std::fwrite(hs.data(), 1, hs.size(), f) == hs.size();
    for (auto& [name, a] : arrays) ok = ok && std::fwrite(a->data(), 4, a->size(), f) == a->size();
    ok = (std::fclose(f) == 0) && ok;
    if (!ok) fail("{}: write failed (disk full?)", path.string());
  });
}

void Trainer::load_checkpoint(const std::filesystem::path& path) {
  using nlohmann::json;
  const std::string where = path.string();
  std::vector<uint8_t> bytes = read_file_bytes(path);
  if (bytes.size() < 16 || std::memcmp(bytes.data(), kMagic, 8) != 0) fail("{}: not an hgs checkpoint", where);
  uint64_t len;
  std::memcpy(&len, bytes.data() + 8, 8);
  if (len > bytes.size() - 16) fail("{}: truncated checkpoint header", where);
  json h;
  try {
    h = json::parse(bytes.begin() + 16, bytes.begin() + 16 + len);
  } catch (const std::exception& e) {
    fail("{}: corrupt checkpoint header", where);
  }
  try {
    if (h.at("num_views").get<size_t>() != views_.size())
      fail("{}: checkpoint was trained on {} views, this scene has {}", where, h.at("num_views").get<size_t>(), views_.size());
    TrainConfig c = TrainConfig::from_json(h.at("config"), where);
    c.iters = cfg_.iters;
    c.save_every = cfg_.save_every;
    GaussianModel m;
    m.sh_degree = h.at("sh_degree").get<int>();
    m.resize(h.at("n").get<int>());
    for (auto& e : h.at("extras")) m.add_extra(e.at("name").get<std::string>(), e.at("dim").get<int>());
    Adam a;
    a.step_count = h.at("adam").at("step").get<long>();
    for (auto& p : h.at("adam").at("params")) {
      AdamParam& ap = a.add(p.at("name").get<std::string>(), p.at("dim").get<int>(), m.n, 0.f, p.value("bf16", false));
      ap.lr = p.at("lr").get<std::vector<float>>();
      if (int(ap.lr.size()) != ap.dim) fail("{}: parameter '{}' has {} learning rates for {} columns", where, ap.name, ap.lr.size(), ap.dim);
    }
    DensifyStats st;
    st.reset(m.n);
    std::vector<float> counts(m.n);
    std::map<std::string, std::vector<float>*> dst;
    for (auto& f : m.fields()) dst["model/" + f.name] = f.data;
    std::map<std::string, std::vector<float>> narrow;  // bfloat16 moments, read as float32
    for (auto& p : a.params) {
      if (p.bf16) {
        dst["adam_m/" + p.name] = &(narrow["m/" + p.name] = std::vector<float>(p.m16.size()));
        dst["adam_v/" + p.name] = &(narrow["v/" + p.name] = std::vector<float>(p.v16.size()));
      } else {
        dst["adam_m/" + p.name] = &p.m;
        dst["adam_v/" + p.name] = &p.v;
      }
    }
    // The method's own state is read into copies (sized by the file) and committed with the rest.
    std::map<std::string, std::vector<float>> method;
    for (auto& [name, arr] : method_state()) dst["method/" + name] = &(method[name] = std::vector<float>(arr->size()));
    dst["stats/grad_accum"] = &st.grad_accum;
    dst["stats/count"] = &counts;
    dst["stats/max_radius"] = &st.max_radius;
    size_t off = 16 + len;
    size_t seen = 0;
    for (auto& ar : h.at("arrays")) {
      std::string name = ar.at("name").get<std::string>();
      size_t count = ar.at("count").get<size_t>();
      auto it = dst.find(name);
      if (it == dst.end()) fail("{}: unexpected array '{}'", where, name);
      if (name.rfind("method/", 0) == 0) it->second->resize(count);  // sizes checked by method_state_loaded
      if (it->second->size() != count) fail("{}: array '{}' has {} values, expected {}", where, name, count, it->second->size());
      if (bytes.size() - off < count * 4) fail("{}: truncated checkpoint (array '{}')", where, name);
      std::memcpy(it->second->data(), bytes.data() + off, count * 4);
      off += count * 4;
      ++seen;
    }
    if (seen != dst.size()) fail("{}: checkpoint holds {} arrays, expected {}", where, seen, dst.size());
    for (int i = 0; i < m.n; ++i) st.count[i] = int(counts[i]);
    for (auto& p : a.params) {
      if (!p.bf16) continue;
      const auto& fm = narrow["m/" + p.name];
      const auto& fv = narrow["v/" + p.name];
      for (size_t i = 0; i < fm.size(); ++i) p.m16[i] = float_to_bf16(fm[i]);  // exact: written from bfloat16
      for (size_t i = 0; i < fv.size(); ++i) p.v16[i] = float_to_bf16(fv[i]);
    }
    std::istringstream rs(h.at("rng").get<std::string>());
    std::mt19937_64 rng;
    rs >> rng;
    if (rs.fail()) fail("{}: corrupt random-generator state", where);
    std::vector<int> order = h.at("order").get<std::vector<int>>();
    for (int o : order)
      if (o < 0 || o >= int(views_.size())) fail("{}: corrupt view order", where);
    // Everything parsed: commit. Trainable extras keep a gradient buffer.
    for (auto& [name, g] : extra_grads_) {
      const ExtraGroup* e = m.find_extra(name);
      if (!e) fail("{}: the checkpoint has no '{}' channels", where, name);
      g.assign(size_t(m.n) * e->dim, 0.f);
    }
    for (auto& [name, arr] : method_state()) *arr = std::move(method[name]);
    method_state_loaded(where);
    cfg_ = c;
    model_ = std::move(m);
    adam_ = std::move(a);
    stats_ = std::move(st);
    rng_ = rng;
    order_ = std::move(order);
    order_pos_ = h.at("order_pos").get<size_t>();
    it_ = h.at("iteration").get<int>();
    extent_ = h.at("extent").get<float>();
    model_.validate(where);
  } catch (const json::exception& e) {
    fail("{}: malformed checkpoint header ({})", where, e.what());
  }
}

}  // namespace hgs::train
