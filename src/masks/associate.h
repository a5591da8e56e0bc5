// `hgs masks associate`: per-view masks whose ids mean nothing across views (hgs masks import, hgs synth
// --mask-ids per-view) -> one id per physical object in every view, by lifting the masks to 3D through COLMAP's
// 2D-3D correspondences (images.bin: the 3D point each keypoint observes).
//
// Steps: (1) every mask of every view becomes a node; with masks/import.json, parts are first joined to their
// whole when they tile it (the whole kept less than half of its pixels after flattening, or its parts add up to
// half its area: SAM's whole + parts, not a table holding a few things); part_of comes from import.json (90%
// overlap) or, when SAM's files are still at import.json's source, is recomputed at part_fraction, and the
// parts folded into a whole are clipped to the whole's own mask (whole_pixels; clip_parts_to_wholes, per_view.h);
// (2) nodes covering more than max_area of the image are dropped as background, nodes with fewer than
// min_points 3D points as unliftable; (3) the graph of nodes linked by shared 3D points is clustered (cluster.h);
// (4) clusters seen in fewer than min_views views are dropped; every remaining cluster is one object, numbered by
// views (most first); (5) every 3D point votes for the object most of its masks belong to, and a mask left out
// (too few points to cluster, or alone) joins the object holding at least half of its points when that object
// has no mask in its view yet (sparse points on small or far objects). Names come from a names file or
// masks/objects.json by majority over the object's masks. Output: masks/<stem>.png with the object ids,
// masks/objects.json, masks/associate.json (report) and the input kept in masks/per_view/ (or everything in --out-masks
// DIR). All written into a temporary folder and moved into place at the end.
//
// Tracks (optional, AssociateOptions::tracks): with SAM2-style input the ids already link views; the clustering
// starts from each track's segments (cluster.h) instead of single masks, so a track is kept where 3D says nothing
// and cut where its points jump to another object (an identity swap).
//
// Depth (optional): with a z-depth map per view (AssociateOptions::depth), every pixel on a grid is lifted too and
// re-projected into the other views where their depth agrees (depth_tracks.h); those tracks join COLMAP's points.
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace hgs::masks {

struct AssociateOptions {
  std::filesystem::path scene;
  std::filesystem::path out_masks;  // empty: in place (SCENE/masks, originals kept in SCENE/masks/per_view)
  std::filesystem::path names;      // optional {"<stem>": {"<id>": "name"}} per-view names
  double min_affinity = 0.3;        // two-way containment to merge (cluster.h)
  int min_views = 2;                // objects seen in fewer views are dropped
  int min_points = 3;               // masks with fewer 3D points cannot be lifted and are dropped
  int core_margin = 2;    // keypoints closer than this (px) to a mask's boundary do not lift it (SAM's edge errors)
  double max_area = 0.8;  // masks covering a larger fraction of their image are background
  bool attach = true;     // masks left out (few points, alone) join the object holding most of their points
  bool join_parts = true;
  double part_merge = 0.5;  // a cluster inside another's whole masks joins it as a part (cluster.h)
  // A part folded into its whole keeps only its pixels inside the whole (clip_parts_to_wholes, per_view.h); needs
  // SAM's own masks at import.json's source (sam-json, sam-png). false = the union of the whole and its parts.
  bool whole_pixels = true;
  // Confidence of the written masks imported from SAM's files (per-mask scores) or without a confidence file: their
  // own times an edge ramp over this many pixels (edge_ramp_confidence, per_view.h); 0 = the input's as they are.
  // Per-pixel confidences of other sources are always kept.
  int edge_ramp = 4;
  double part_fraction = 0.5;    // with SAM's masks still at import.json's source: part_of recomputed at this overlap
  bool drop_surfaces = false;    // drop objects whose 3D spread is larger than surface_spread (walls, floor, table)
  double surface_spread = 0.17;  // spread of an object's points / spread of all points (robust_spread, per_view.h)
  // Optional dense correspondences: z-depth [H, W] of a view (empty = none for that view; <= 0 = no depth at a
  // pixel), e.g. rendered from a short RGB training; null = COLMAP's points only.
  std::function<std::vector<float>(const View&)> depth;
  int depth_stride = 0;           // lift every stride-th pixel; 0 = about 4096 pixels per view
  double depth_tolerance = 0.03;  // relative depth agreement for a lifted point to count as seen by another view
  // The input's ids are tracks (SAM2 label maps, `hgs synth`'s masks): consistent across views but wrong in runs.
  // A mask continues its track's object unless the 3D points measure them apart (neither contains the other:
  // both average containments below track_split, cluster.h); masks with too few points ride their track instead of
  // being dropped. false: ids mean nothing across views (SAM's per-view masks).
  bool tracks = false;
  double track_split = 0.1;  // chosen on the development seeds (docs/association.md)
  bool force = false;        // re-associate an already associated scene (from masks/per_view) / replace out_masks
  bool progress = true;
};

struct AssociatedObject {
  int id = 0;
  std::string name;
  int views = 0;         // views with a mask of this object
  int masks = 0;         // nodes (after joining parts)
  long points = 0;       // 3D points it holds
  double spread = 0;     // RMS spread of its points relative to all points
  bool surface = false;  // spread > surface_spread
};

struct AssociateSummary {
  int views = 0, views_with_masks = 0;
  int masks = 0;         // nodes considered (after joining parts)
  int joined_parts = 0;  // per-view masks folded into their whole
  int attached = 0;      // masks left out of the clustering that joined an object by their points' votes
  std::vector<AssociatedObject> objects;
  long colmap_points = 0, depth_points = 0;  // 3D points used (depth: lifted pixels seen by another view)
  int dropped_background = 0, dropped_few_points = 0, dropped_few_views = 0, dropped_surface = 0;
  std::filesystem::path out_dir, backup_dir;  // where the masks went, where the originals are (empty with --out-masks)
};

AssociateSummary associate_masks(const AssociateOptions& opt);

}  // namespace hgs::masks
