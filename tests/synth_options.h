// SmallSynth: the synth::SynthOptions of a small test scene, with chained setters for what a test changes.
// It starts at 16 views of 96x72 pixels, 4 objects, 3000 SfM points, 32-dimensional features, one sample per
// pixel and no progress output; every other field keeps SynthOptions' default (seed 1, medium noise, consistent
// label masks). Used by the tests and by the fuzz harnesses' tiny scene.
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
  operator synth::SynthOptions() const { return o_; }

 private:
  synth::SynthOptions o_{.views = 16,
                         .width = 96,
                         .height = 72,
                         .objects = 4,
                         .points = 3000,
                         .feature_dim = 32,
                         .supersample = 1,
                         .progress = false};
};

}  // namespace hgs::test
