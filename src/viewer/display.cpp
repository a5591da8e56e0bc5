#include "viewer/display.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>

#include "core/error.h"
#include "core/fs.h"
#include "hybrid/fields.h"
#include "model/ply.h"
#include "query/query.h"

namespace hgs::viewer {
namespace fs = std::filesystem;

GaussianModel display_model(const GaussianModel& m, const DisplayOptions& opt) {
  GaussianModel out = m;
  if (opt.show != Show::all) out = query::select_objects(m, opt.objects, opt.show == Show::remove);
  if (opt.tint && !opt.objects.empty() && opt.show != Show::remove) {
    const ExtraGroup* z = hybrid::ConstHybridFields::bind(out, "viewer").z;
    const int S = out.sh_stride();
    for (int i = 0; i < out.n; ++i) {
      if (std::find(opt.objects.begin(), opt.objects.end(), int(z->data[i])) == opt.objects.end()) continue;
      for (int c = 0; c < 3; ++c) {
        float& dc = out.sh[size_t(i) * S * 3 + c];
        const float rgb = (1.f - opt.tint_amount) * sh_to_rgb(dc) + opt.tint_amount * opt.tint_rgb[c];
        dc = rgb_to_sh(rgb);
      }
      // Make the tint visible from every side: view-dependent colour off, opacity at least 0.8.
      for (int k = 1; k < S; ++k)
        for (int c = 0; c < 3; ++c) out.sh[(size_t(i) * S + k) * 3 + c] = 0.f;
      out.opacity_logit[i] = std::max(out.opacity_logit[i], inverse_sigmoid(0.8f));
    }
  }
  if (!opt.keep_extras) out.extras.clear();
  return out;
}

std::string ply_bytes(const GaussianModel& m) {
  static std::atomic<long> counter{0};
  const fs::path tmp =
      fs::temp_directory_path() / ("hgs-view-" + std::to_string(::getpid()) + "-" + std::to_string(counter++) + ".ply");
  struct Remove {
    fs::path p;
    ~Remove() {
      std::error_code ec;
      fs::remove(p, ec);
    }
  } guard{tmp};
  write_model_ply(tmp, m);
  std::vector<uint8_t> b = read_file_bytes(tmp);
  return std::string(b.begin(), b.end());
}

}  // namespace hgs::viewer
