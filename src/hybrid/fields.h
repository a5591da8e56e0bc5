// The hybrid fields of a GaussianModel, bound once by name and checked: q [N, L] (soft object association,
// extra group "obj"), z [N, 1] (hard id argmax q, "obj_id", stored as float) and f [N, D] (language embedding,
// "lang", float32 or IEEE half). Trainer, query, export and viewer use this binding instead of looking the
// groups up by string. The pointers follow the model's extras vector: rebind after adding extra groups.
#pragma once
#include <string>

#include "core/error.h"
#include "model/gaussian_model.h"

namespace hgs::hybrid {

inline constexpr const char* kAssociationGroup = "obj";  // q
inline constexpr const char* kHardIdGroup = "obj_id";    // z
inline constexpr const char* kLanguageGroup = "lang";    // f

template <class Model, class Group>
struct HybridFieldsT {
  Group* q = nullptr;  // [N, L]
  Group* z = nullptr;  // [N, 1]
  Group* f = nullptr;  // [N, D]
  int num_labels = 0;  // L = K + 1
  int dim = 0;         // D

  // Binds the three groups of `m`; throws hgs::Error naming `where` when one is missing or misshapen.
  static HybridFieldsT bind(Model& m, const std::string& where) {
    HybridFieldsT b;
    b.q = m.find_extra(kAssociationGroup);
    b.z = m.find_extra(kHardIdGroup);
    b.f = m.find_extra(kLanguageGroup);
    if (!b.q || !b.z || !b.f)
      fail("{}: the model has no object associations / language embeddings (train it with --method hybrid)", where);
    if (b.z->dim != 1) fail("{}: the hard object ids have {} values per Gaussian (expected 1)", where, b.z->dim);
    if (b.q->dim < 1) fail("{}: the model has no object channels", where);
    if (b.q->f16 || b.z->f16) fail("{}: object associations must be stored as float32", where);
    b.num_labels = b.q->dim;
    b.dim = b.f->dim;
    return b;
  }
  // True when all three groups are present (a hybrid model).
  static bool present(const Model& m) {
    return m.find_extra(kAssociationGroup) && m.find_extra(kHardIdGroup) && m.find_extra(kLanguageGroup);
  }
  const float* q_row(int i) const { return q->data.data() + size_t(i) * num_labels; }
  int hard_id(int i) const { return static_cast<int>(z->data[size_t(i)]); }
};

using HybridFields = HybridFieldsT<GaussianModel, ExtraGroup>;
using ConstHybridFields = HybridFieldsT<const GaussianModel, const ExtraGroup>;

}  // namespace hgs::hybrid
