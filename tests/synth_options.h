// SmallSynth: the synth::SynthOptions of a small test scene, with chained setters for what a test changes.
// It starts at 16 views of 96x72 pixels, 4 objects, 3000 SfM points, 32-dimensional features, one sample per
// pixel and no progress output, in the simple world's objects-only variant (masks of the objects alone, no
// small-object misses, no parts: the world the tests' margins were measured on; sam_like() adds the simple world's
// surfaces, misses and parts, realistic() switches to `hgs synth`'s default world, language.h / tracks.h); every
// other field keeps SynthOptions' default (seed 1, medium noise, consistent label masks). Used by the tests and by
// the fuzz harnesses' tiny scene.
#pragma once
#include <cstdint>
#include <string>

#include "synth/synth.h"

namespace hgs::test {

class SmallSynth {
 public:
  SmallSynth& seed(uint64_t v) {
    o_.seed = v;
    return *this;
  }
  SmallSynth& views(int v) {
    o_.views = v;
    return *this;
  }
  SmallSynth& image_size(int width, int height) {
    o_.width = width;
    o_.height = height;
    return *this;
  }
  SmallSynth& objects(int v) {
    o_.objects = v;
    return *this;
  }
  SmallSynth& points(int v) {
    o_.points = v;
    return *this;
  }
  SmallSynth& feature_dim(int v) {
    o_.feature_dim = v;
    return *this;
  }
  SmallSynth& noise(const std::string& v) {
    o_.noise = v;
    return *this;
  }
  SmallSynth& sam_like() {  // the default world of `hgs synth`: surfaces, small-object misses, parts
    const synth::SynthOptions d;
    o_.surface_masks = d.surface_masks;
    o_.small_miss_rate = d.small_miss_rate;
    o_.split_rate = d.split_rate;
    return *this;
  }
  SmallSynth& realistic() {  // `hgs synth`'s default world, with its surfaces, misses and parts
    o_.world = "realistic";
    return sam_like();
  }
  operator synth::SynthOptions() const { return o_; }

 private:
  synth::SynthOptions o_{.world = "simple",
                         .views = 16,
                         .width = 96,
                         .height = 72,
                         .objects = 4,
                         .points = 3000,
                         .feature_dim = 32,
                         .supersample = 1,
                         .surface_masks = false,
                         .small_miss_rate = 0,
                         .split_rate = 0,
                         .progress = false};
};

}  // namespace hgs::test
