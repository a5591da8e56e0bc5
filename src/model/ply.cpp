// PLY reader/writer for Gaussian models. The writer emits the fixed 3DGS layout; the reader parses the
// header into (name, type, offset) properties, maps them to model arrays by name and then decodes the body
// row by row, so the property order in the file does not matter.
#include "model/ply.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>
#include <sstream>
#include <utility>

#include "core/error.h"
#include "core/fs.h"

namespace hgs {
namespace {

bool valid_group_name(const std::string& s) {
  if (s.empty() || s.rfind("f_", 0) == 0) return false;
  for (char c : s)
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_')) return false;
  static const char* reserved[] = {"x", "y", "z", "nx", "ny", "nz", "opacity"};
  for (auto r : reserved)
    if (s == r) return false;
  return s.rfind("scale_", 0) != 0 && s.rfind("rot_", 0) != 0;
}

std::vector<std::string> property_names(const GaussianModel& m) {
  std::vector<std::string> names = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"};
  for (int i = 0; i < 3 * (m.sh_stride() - 1); ++i) names.push_back(fmt::format("f_rest_{}", i));
  names.push_back("opacity");
  for (int i = 0; i < 3; ++i) names.push_back(fmt::format("scale_{}", i));
  for (int i = 0; i < 4; ++i) names.push_back(fmt::format("rot_{}", i));
  for (auto& e : m.extras) {
    if (e.dim == 1) names.push_back(e.name);
    else
      for (int i = 0; i < e.dim; ++i) names.push_back(fmt::format("f_{}_{}", e.name, i));
  }
  return names;
}

struct Prop {
  std::string name;
  int type;  // index into kTypes
  size_t offset;
};

struct TypeInfo {
  const char* names[2];
  int size;
};
const TypeInfo kTypes[] = {{{"float", "float32"}, 4}, {{"double", "float64"}, 8}, {{"uchar", "uint8"}, 1},
                           {{"char", "int8"}, 1},     {{"ushort", "uint16"}, 2},  {{"short", "int16"}, 2},
                           {{"uint", "uint32"}, 4},   {{"int", "int32"}, 4}};

float decode(const uint8_t* p, int type) {
  switch (type) {
    case 0: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    case 1: {
      double v;
      std::memcpy(&v, p, 8);
      return float(v);
    }
    case 2: return float(*p);
    case 3: return float(int8_t(*p));
    case 4: {
      uint16_t v;
      std::memcpy(&v, p, 2);
      return float(v);
    }
    case 5: {
      int16_t v;
      std::memcpy(&v, p, 2);
      return float(v);
    }
    case 6: {
      uint32_t v;
      std::memcpy(&v, p, 4);
      return float(v);
    }
    default: {
      int32_t v;
      std::memcpy(&v, p, 4);
      return float(v);
    }
  }
}

// Parses "<prefix><integer>" -> integer, or -1.
int suffix_index(const std::string& s, const std::string& prefix) {
  if (s.size() <= prefix.size() || s.compare(0, prefix.size(), prefix) != 0) return -1;
  int v = 0;
  for (size_t i = prefix.size(); i < s.size(); ++i) {
    if (s[i] < '0' || s[i] > '9' || v > 100000) return -1;
    v = v * 10 + (s[i] - '0');
  }
  if (s.size() - prefix.size() > 1 && s[prefix.size()] == '0') return -1;  // no leading zeros
  return v;
}

}  // namespace

namespace {
// The index of the first NaN / infinite value of a[0, n) and how many there are (first = n: none).
template <class Get>
std::pair<size_t, size_t> nonfinite_in(size_t n, const Get& get) {
  size_t first = n, count = 0;
#pragma omp parallel for reduction(min : first) reduction(+ : count)
  for (size_t k = 0; k < n; ++k)
    if (!std::isfinite(get(k))) first = std::min(first, k), ++count;
  return {first, count};
}

// read_model_ply refuses a body with NaN or infinite values: refuse them here, before anything is written, naming
// the array as Python's hgs.Model does (means, log_scales, rotations, opacity_logits, sh, extras['<group>']).
void check_finite(const std::filesystem::path& path, const GaussianModel& m) {
  auto check = [&](const std::string& name, size_t n, size_t per_gaussian, const auto& get) {
    const auto [first, count] = nonfinite_in(n, get);
    if (count > 0)
      fail(
          "{}: not written: {} holds {} NaN or infinite value{} (the first at Gaussian {}); a model file must be "
          "finite to load",
          path.string(), name, count, count == 1 ? "" : "s", first / std::max<size_t>(1, per_gaussian));
  };
  auto flat = [&](const char* name, const std::vector<float>& v, size_t per) {
    check(name, v.size(), per, [&](size_t k) { return v[k]; });
  };
  flat("means", m.mean, 3);
  flat("log_scales", m.log_scale, 3);
  flat("rotations", m.quat, 4);
  flat("opacity_logits", m.opacity_logit, 1);
  flat("sh", m.sh, size_t(m.sh_stride()) * 3);
  for (const ExtraGroup& e : m.extras)
    check("extras['" + e.name + "']", size_t(m.n) * size_t(e.dim), size_t(e.dim), [&](size_t k) { return e.value(k); });
}
}  // namespace

void write_model_ply(const std::filesystem::path& path, const GaussianModel& m) {
  m.validate(path.string());
  check_finite(path, m);
  for (auto& e : m.extras)
    if (!valid_group_name(e.name))
      fail("{}: extra channel group name '{}' is not writable (use [a-z0-9_], not starting with f_)", path.string(),
           e.name);
  auto names = property_names(m);
  std::string header = "ply\nformat binary_little_endian 1.0\ncomment written by hgs " HGS_VERSION "\n";
  header += fmt::format("element vertex {}\n", m.n);
  for (auto& nm : names) header += "property float " + nm + "\n";
  header += "end_header\n";
  const size_t row = names.size();
  const int S = m.sh_stride();
  std::vector<float> body(size_t(m.n) * row);
#pragma omp parallel for
  for (long i = 0; i < m.n; ++i) {
    float* r = body.data() + size_t(i) * row;
    size_t k = 0;
    for (int c = 0; c < 3; ++c) r[k++] = m.mean[i * 3 + c];
    for (int c = 0; c < 3; ++c) r[k++] = 0.f;
    const float* sh = m.sh.data() + size_t(i) * S * 3;
    for (int c = 0; c < 3; ++c) r[k++] = sh[c];
    for (int c = 0; c < 3; ++c)
      for (int j = 1; j < S; ++j) r[k++] = sh[j * 3 + c];
    r[k++] = m.opacity_logit[i];
    for (int c = 0; c < 3; ++c) r[k++] = m.log_scale[i * 3 + c];
    for (int c = 0; c < 4; ++c) r[k++] = m.quat[i * 4 + c];
    for (auto& e : m.extras) {
      e.row(i, r + k);  // half-precision groups are widened: files hold float32
      k += e.dim;
    }
  }
  static_assert(sizeof(float) == 4);
  atomic_write(path, [&](const std::filesystem::path& tmp) {
    FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) fail("{}: cannot open for writing", path.string());
    bool ok = std::fwrite(header.data(), 1, header.size(), f) == header.size() &&
              (body.empty() || std::fwrite(body.data(), sizeof(float), body.size(), f) == body.size());
    ok = (std::fclose(f) == 0) && ok;
    if (!ok) fail("{}: write failed (disk full?)", path.string());
  });
}

namespace {

// The vertex element of a PLY header: its properties, vertex count and row size, and where the body starts.
struct PlyHeader {
  std::vector<Prop> props;
  long count = -1;
  size_t row = 0;   // bytes per vertex
  size_t body = 0;  // offset of the body in the file
};

PlyHeader read_header(const std::vector<uint8_t>& bytes, const std::string& where) {
  size_t pos = 0;
  auto next_line = [&](std::string& line) {
    size_t e = pos;
    while (e < bytes.size() && bytes[e] != '\n') ++e;
    if (e >= bytes.size()) fail("{}: PLY header is not terminated by end_header", where);
    line.assign(reinterpret_cast<const char*>(bytes.data()) + pos, e - pos);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    pos = e + 1;
  };
  PlyHeader h;
  std::vector<Prop>& props = h.props;
  long& count = h.count;
  size_t& row = h.row;
  std::string line;
  if (bytes.size() < 4 || std::memcmp(bytes.data(), "ply", 3) != 0 || (bytes[3] != '\n' && bytes[3] != '\r'))
    fail("{}: not a PLY file (first line is not 'ply')", where);
  next_line(line);
  if (line != "ply") fail("{}: not a PLY file (first line is not 'ply')", where);
  bool in_vertex = false, seen_format = false;
  int lineno = 1;
  while (true) {
    next_line(line);
    ++lineno;
    std::istringstream ls(line);
    std::string kw;
    ls >> kw;
    if (kw == "end_header") break;
    if (kw == "comment" || kw == "obj_info" || kw.empty()) continue;
    if (kw == "format") {
      std::string fmt_, ver;
      ls >> fmt_ >> ver;
      if (fmt_ == "ascii") fail("{}: ASCII PLY is not supported; write binary_little_endian", where);
      if (fmt_ == "binary_big_endian") fail("{}: big-endian PLY is not supported; write binary_little_endian", where);
      if (fmt_ != "binary_little_endian") fail("{}: header line {}: unknown PLY format '{}'", where, lineno, fmt_);
      seen_format = true;
    } else if (kw == "element") {
      std::string name;
      long c = -1;
      std::string extra;
      ls >> name >> c;
      // A count like "0.2" reads as 0 and leaves ".2", which `extra` catches.
      if (ls.fail() || c < 0 || (ls >> extra))
        fail("{}: header line {}: malformed element line '{}'", where, lineno, line);
      in_vertex = name == "vertex";
      if (in_vertex) {
        if (count >= 0) fail("{}: more than one vertex element", where);
        if (c > (1L << 31) - 1) fail("{}: vertex count {} is too large", where, c);
        count = c;
      } else if (count < 0 && c > 0) {
        fail("{}: element '{}' before the vertex element is not supported", where, name);
      }
    } else if (kw == "property") {
      if (!in_vertex) continue;  // properties of ignored elements after vertex
      std::string type, name;
      ls >> type >> name;
      if (type == "list")
        fail("{}: header line {}: list property in the vertex element is not supported", where, lineno);
      if (ls.fail() || name.empty()) fail("{}: header line {}: malformed property line '{}'", where, lineno, line);
      int t = -1;
      for (int i = 0; i < 8; ++i)
        if (type == kTypes[i].names[0] || type == kTypes[i].names[1]) t = i;
      if (t < 0) fail("{}: header line {}: unknown property type '{}'", where, lineno, type);
      for (auto& p : props)
        if (p.name == name) fail("{}: property '{}' appears twice", where, name);
      props.push_back({name, t, row});
      row += kTypes[t].size;
    } else {
      fail("{}: header line {}: unexpected '{}'", where, lineno, line);
    }
  }
  if (!seen_format) fail("{}: PLY header has no format line", where);
  if (count < 0) fail("{}: PLY has no vertex element", where);
  const size_t body = bytes.size() - pos;
  if (body < size_t(count) * row)
    fail("{}: truncated body: {} vertices of {} bytes need {} bytes, file has {}", where, count, row,
         size_t(count) * row, body);
  h.body = pos;
  return h;
}

const char* const kRequired[] = {"x",       "y",       "z",       "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                 "scale_0", "scale_1", "scale_2", "rot_0",  "rot_1",  "rot_2",  "rot_3"};

// The properties beyond the 3DGS ones: the SH rest count and the extra channel groups f_<name>_<i> (in file order).
struct ExtraProps {
  int n_rest = 0;
  std::map<std::string, std::map<int, const Prop*>> groups;
  std::vector<std::string> group_order;
};

ExtraProps classify_props(const std::vector<Prop>& props, const std::string& where) {
  ExtraProps x;
  for (auto& p : props) {
    int idx;
    if ((idx = suffix_index(p.name, "f_rest_")) >= 0) {
      x.n_rest = std::max(x.n_rest, idx + 1);
      continue;
    }
    bool standard = false;
    for (auto r : kRequired) standard |= p.name == r;
    if (standard || p.name == "nx" || p.name == "ny" || p.name == "nz") continue;
    std::string gname = p.name;
    idx = 0;
    if (p.name.rfind("f_", 0) == 0) {
      size_t us = p.name.rfind('_');
      idx = us > 2 ? suffix_index(p.name, p.name.substr(0, us + 1)) : -1;
      if (idx < 0) fail("{}: property '{}' does not follow the f_<group>_<index> pattern", where, p.name);
      gname = p.name.substr(2, us - 2);
      if (gname == "dc" || gname == "rest") fail("{}: unexpected property '{}'", where, p.name);
    }
    if (!x.groups.count(gname)) x.group_order.push_back(gname);
    auto& g = x.groups[gname];
    if (g.count(idx)) fail("{}: extra channel '{}' is given twice", where, p.name);
    g[idx] = &p;
  }
  return x;
}

// Destination of one property: element i goes to (*v)[i * stride + offset]. (Offsets, not pointers: with zero
// Gaussians the arrays are empty and `data() + c` would offset a null pointer, which UBSan reports.)
struct Slot {
  const Prop* p;
  std::vector<float>* v;
  size_t offset, stride;
};

// The slots of every property read into `m` (sized, SH degree set); adds m's extra groups.
std::vector<Slot> model_slots(GaussianModel& m, ExtraProps& x,
                              const std::function<const Prop*(const std::string&)>& need, const std::string& where) {
  std::vector<Slot> slots;
  const int S = m.sh_stride();
  for (int c = 0; c < 3; ++c) slots.push_back({need(std::string(1, "xyz"[c])), &m.mean, size_t(c), 3});
  for (int c = 0; c < 3; ++c) slots.push_back({need(fmt::format("f_dc_{}", c)), &m.sh, size_t(c), size_t(S) * 3});
  for (int c = 0; c < 3; ++c)
    for (int j = 1; j < S; ++j)
      slots.push_back({need(fmt::format("f_rest_{}", c * (S - 1) + j - 1)), &m.sh, size_t(j * 3 + c), size_t(S) * 3});
  slots.push_back({need("opacity"), &m.opacity_logit, 0, 1});
  for (int c = 0; c < 3; ++c) slots.push_back({need(fmt::format("scale_{}", c)), &m.log_scale, size_t(c), 3});
  for (int c = 0; c < 4; ++c) slots.push_back({need(fmt::format("rot_{}", c)), &m.quat, size_t(c), 4});
  for (auto& gname : x.group_order) {
    auto& g = x.groups[gname];
    int dim = int(g.size());
    for (int i = 0; i < dim; ++i)
      if (!g.count(i)) fail("{}: extra channel group '{}' has {} channels but no index {}", where, gname, dim, i);
    m.add_extra(gname, dim);
    for (int i = 0; i < dim; ++i) slots.push_back({g[i], nullptr, size_t(i), size_t(dim)});
  }
  // Resolve extra destinations once every group is added (add_extra may reallocate `extras`).
  size_t s = slots.size();
  for (int gi = int(m.extras.size()) - 1; gi >= 0; --gi) {
    auto& e = m.extras[gi];
    s -= e.dim;
    for (int i = 0; i < e.dim; ++i) slots[s + i].v = &e.data;
  }
  return slots;
}

}  // namespace

GaussianModel read_model_ply(const std::filesystem::path& path) {
  const std::string where = path.string();
  std::vector<uint8_t> bytes = read_file_bytes(path);
  const PlyHeader h = read_header(bytes, where);
  // Map properties to model slots.
  std::map<std::string, const Prop*> by_name;
  for (auto& p : h.props) by_name[p.name] = &p;
  auto need = [&](const std::string& nm) {
    auto it = by_name.find(nm);
    if (it == by_name.end()) fail("{}: missing property '{}'", where, nm);
    return it->second;
  };
  for (auto r : kRequired) need(r);
  ExtraProps x = classify_props(h.props, where);
  int degree = -1;
  for (int d = 0; d <= 3; ++d)
    if (x.n_rest == 3 * ((d + 1) * (d + 1) - 1)) degree = d;
  if (degree < 0) fail("{}: {} f_rest properties; expected 0, 9, 24 or 45 (SH degree 0..3)", where, x.n_rest);
  for (int i = 0; i < x.n_rest; ++i) need(fmt::format("f_rest_{}", i));

  GaussianModel m;
  m.sh_degree = degree;
  m.resize(int(h.count));
  const std::vector<Slot> slots = model_slots(m, x, need, where);
  const uint8_t* base = bytes.data() + h.body;
  const size_t row = h.row;
  bool nonfinite = false;
#pragma omp parallel for reduction(|| : nonfinite)
  for (long i = 0; i < h.count; ++i) {
    const uint8_t* r = base + size_t(i) * row;
    for (auto& s : slots) {
      float v = decode(r + s.p->offset, s.p->type);
      nonfinite = nonfinite || !std::isfinite(v);
      (*s.v)[size_t(i) * s.stride + s.offset] = v;
    }
  }
  if (nonfinite) fail("{}: the body holds NaN or infinite values", where);
  return m;
}

}  // namespace hgs
