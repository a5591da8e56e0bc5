// HybridConfig as JSON (MODEL/config.json, checkpoints): every field by name, through one list of the fields.
#include "hybrid/config.h"

#include "core/error.h"

namespace hgs::hybrid {

// clang-format off
#define HGS_HYBRID_FIELDS(X) \
  X(use_of) X(use_scl) X(use_bro) X(lambda_rgb) X(lambda_app) X(lambda_sem) X(lambda_bro) X(lambda_dssim) \
  X(tau1) X(unconfident_unobserved) X(gaps) X(occlusion_test) X(background_vote) X(temperature) X(fusion_eps) X(tau2) \
  X(scl_background) X(fusion_every) X(bro_kernel) X(bro_scale_invariant) X(bro_image_norm) X(sem_geometry) \
  X(bro_eps) X(min_mask_pixels) X(lr_lang) X(lang_half) X(lr_view) X(lang_init_std) X(objects_per_step) \
  X(sparse_objects)
// clang-format on

nlohmann::json HybridConfig::to_json() const {
  nlohmann::json j;
#define X(f) j[#f] = f;
  HGS_HYBRID_FIELDS(X)
#undef X
  return j;
}

HybridConfig HybridConfig::from_json(const nlohmann::json& j) {
  HybridConfig c;
#define X(f) \
  if (j.contains(#f)) j.at(#f).get_to(c.f);
  HGS_HYBRID_FIELDS(X)
#undef X
  // A configuration written before background_vote existed (an older checkpoint) was trained with eq. 4 as
  // written; its occlusion_test field, false then, is read above.
  if (!j.is_null() && !j.contains("background_vote")) c.background_vote = 1.0f;
  // Likewise one written before scl_background: eq. 10 without the background.
  if (!j.is_null() && !j.contains("scl_background")) c.scl_background = "off";
  // And one written before gaps: every unlabelled pixel was background evidence.
  if (!j.is_null() && !j.contains("gaps")) c.gaps = "background";
  if (c.scl_background != "auto" && c.scl_background != "on" && c.scl_background != "off")
    fail("hybrid configuration: scl_background must be auto, on or off (got '{}')", c.scl_background);
  if (c.gaps != "background" && c.gaps != "unobserved" && c.gaps != "auto")
    fail("hybrid configuration: gaps must be background, unobserved or auto (got '{}')", c.gaps);
  if (c.objects_per_step < 0) fail("hybrid configuration: objects_per_step must be >= 0 (got {})", c.objects_per_step);
  return c;
}

}  // namespace hgs::hybrid
