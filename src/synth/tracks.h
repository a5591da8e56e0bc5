// SAM2-like label maps over the capture order (the realistic world's masks): SAM2 propagates one mask per
// object from frame to frame, so its errors come in runs, not afresh in every view as the simple world draws them.
// Walking the views in capture order (views are numbered along the camera path), each object's track
//   - is lost for a run of views (more often when the object is small or suddenly occluded) and comes back under
//     its old id or, re-detected, under a new one (a re-born track, named "<object> (track n)");
//   - keeps one edge bias in every view (SAM over- or under-segments an object the same way from every side),
//     with one pixel of per-view jitter;
//   - shares one mask with a touching object that SAM confuses it with (a pair drawn once), in every view where the
//     two touch (SAM's group granularity);
//   - may swap identities with a touching object, and the swap persists (SAM2's identity switch);
// and every background surface is cut into pieces (Voronoi cells of seed points on it, the same pieces in every
// view) that SAM2 tracks as objects of their own. Parts (the upper half of a split object) are tracked as before.
#pragma once
#include <map>
#include <string>
#include <vector>

#include "core/image.h"
#include "synth/synth.h"

namespace hgs::synth {

// What a mask id truly is in one view.
struct IdTruth {
  int object = 0;       // the object it shows (0: a surface)
  std::string kind;     // "object" | "track" (re-born) | "part" | "surface"
  std::string surface;  // the surface's concept name (kind "surface")
  int piece = 0;        // the surface's piece (1..)
};

class Sam2Simulator {
 public:
  // views: every rendered view in capture order; surfaces[j]: the concept index of background surface j, names
  // its names (the generator's concept list); part_id[k]: the mask id of object k+1's part (0 = none).
  Sam2Simulator(const World& world, const Intrinsics& cam, const std::vector<RenderedView>& views,
                const std::vector<int>& surfaces, const std::vector<std::string>& concept_names,
                const std::vector<int>& part_id, const NoiseLevel& nl, int first_free_id, uint64_t seed);
  // The mask of view i (views must be asked in order 0, 1, ...), its confidence (empty when noise is none) and
  // what each id in it is.
  void next(int i, LabelMap& mask, std::vector<float>& confidence, std::map<int, IdTruth>& truth);
  // Names of every id used so far (objects, re-born tracks, surface pieces, parts): masks/objects.json.
  const std::map<int, std::string>& names() const { return names_; }
  // Mask id of piece p (0-based) of surface j.
  int piece_id(int j, int p) const { return piece_first_[j] + p; }

 private:
  void rebirth(int k);  // object k comes back under a new id

  const World& world_;
  const Intrinsics& cam_;
  const std::vector<RenderedView>& views_;
  std::vector<int> surfaces_;
  std::vector<int> surface_of_concept_;     // concept -> surface index + 1 (0: none)
  std::vector<std::string> surface_names_;  // [S]
  std::vector<int> part_id_;
  NoiseLevel nl_;
  Rng rng_;
  int K_;
  std::vector<int> id_;                             // [K] the id object k+1 shows under now
  std::vector<int> lost_left_;                      // [K] views of the current lost run still to come
  std::vector<char> reborn_;                        // [K] comes back under a new id
  std::vector<int> bias_;                           // [K] signed edge bias (px): > 0 dilates
  std::vector<size_t> last_area_;                   // [K] pixels in the last view that showed it
  std::vector<int> tracks_;                         // [K] re-born tracks so far
  std::map<std::pair<int, int>, bool> merged_;      // touching pairs (a < b) under a's mask in this view
  std::map<std::pair<int, int>, bool> confusable_;  // pairs seen touching: whether SAM takes the two as one
  std::vector<std::vector<Vec3>> seeds_;            // [S] world points of each surface's pieces
  std::vector<int> piece_first_;                    // [S] id of each surface's first piece
  int next_id_;
  std::map<int, std::string> names_;
};

}  // namespace hgs::synth
