// hgs::Error — the one exception type for user-facing failures. Its message is a single line that names the
// file (or option) and what is wrong; the CLI prints it as "hgs: error: <message>" and exits with status 1.
#pragma once
#include <fmt/format.h>
#include <stdexcept>
#include <string>

namespace hgs {

struct Error : std::runtime_error {
  using std::runtime_error::runtime_error;
};

template <typename... Args>
[[noreturn]] inline void fail(fmt::format_string<Args...> f, Args&&... args) {
  throw Error(fmt::format(f, std::forward<Args>(args)...));
}

}  // namespace hgs
