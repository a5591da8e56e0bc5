// fuzz_replay HARNESS PATH...: runs the fuzz harness HARNESS (fuzz.h) once on every file given or found (one
// level) in the given folders, as libFuzzer would, without libFuzzer. Exit 0 when every input ran; a crash, a
// sanitizer report or an exception other than hgs::Error ends the program abnormally. The default test suite runs
// it on each committed corpus (ctest fuzz_smoke_<harness>).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "fuzz.h"

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  auto& reg = hgs::fuzz::registry();
  if (argc < 3 || std::string(argv[1]) == "--help") {
    std::fprintf(stderr, "usage: fuzz_replay HARNESS FILE_OR_FOLDER...\nharnesses:");
    for (auto& [k, v] : reg) std::fprintf(stderr, " %s", k.c_str());
    std::fprintf(stderr, "\n");
    return argc >= 2 && std::string(argv[1]) == "--help" ? 0 : 2;
  }
  auto it = reg.find(argv[1]);
  if (it == reg.end()) {
    std::fprintf(stderr, "fuzz_replay: no harness '%s'\n", argv[1]);
    return 2;
  }
  std::vector<fs::path> files;
  for (int i = 2; i < argc; ++i) {
    if (fs::is_directory(argv[i])) {
      for (auto& e : fs::directory_iterator(argv[i]))
        if (e.is_regular_file()) files.push_back(e.path());
    } else if (fs::is_regular_file(argv[i])) {
      files.push_back(argv[i]);
    } else {
      std::fprintf(stderr, "fuzz_replay: %s: not found\n", argv[i]);
      return 2;
    }
  }
  if (files.empty()) {
    std::fprintf(stderr, "fuzz_replay: no input files\n");
    return 2;
  }
  std::sort(files.begin(), files.end());
  for (auto& f : files) {
    std::ifstream in(f, std::ios::binary);
    std::vector<uint8_t> b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    it->second(b.data(), b.size());
  }
  std::printf("fuzz_replay %s: %zu inputs ran\n", argv[1], files.size());
  return 0;
}
