// Range-checked numbers from JSON. nlohmann-json's get<T>() casts a stored double to an integer or a float
// without a check, which is undefined behaviour when the value does not fit (UBSan's float-cast-overflow, found
// by fuzzing checkpoint headers): json_number<T> returns nullopt instead. Integers accept integral floats (30000.0)
// as get<T> did; floats accept any number whose magnitude fits the type (or is infinite).
#pragma once
#include <cmath>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <type_traits>
#include <utility>

namespace hgs {

template <typename T>
std::optional<T> json_number(const nlohmann::json& v) {
  static_assert(std::is_arithmetic_v<T>);
  if constexpr (std::is_same_v<T, bool>) {
    if (!v.is_boolean()) return std::nullopt;
    return v.get<bool>();
  } else if constexpr (std::is_integral_v<T>) {
    if (v.is_number_unsigned()) {
      const uint64_t u = v.get<uint64_t>();
      if (!std::in_range<T>(u)) return std::nullopt;
      return T(u);
    }
    if (v.is_number_integer()) {
      const int64_t i = v.get<int64_t>();
      if (!std::in_range<T>(i)) return std::nullopt;
      return T(i);
    }
    if (v.is_number_float()) {
      const double d = v.get<double>();
      const double lim = std::ldexp(1.0, std::numeric_limits<T>::digits);  // T holds [-lim, lim) (or [0, lim))
      if (!(d == std::trunc(d) && d < lim && d >= (std::is_signed_v<T> ? -lim : 0.0))) return std::nullopt;
      return T(d);
    }
    return std::nullopt;
  } else {
    if (!v.is_number()) return std::nullopt;
    const double d = v.get<double>();
    if (std::isfinite(d) && std::abs(d) > double(std::numeric_limits<T>::max())) return std::nullopt;
    return T(d);
  }
}

}  // namespace hgs
