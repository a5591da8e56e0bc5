// EXPECT_FILE_ERROR(statement, file, part): `statement` throws hgs::Error (no other exception), whose message is
// one line, names `file` and contains `part` -- what every loader owes bad input (the fuzz regression tests,
// tests/<module>/test_fuzz_regressions.cpp, docs/reliability.md).
#pragma once
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "core/error.h"

#define EXPECT_FILE_ERROR(statement, file, part)                                                             \
  do {                                                                                                       \
    const std::string hgs_file_ = std::filesystem::path(file).string(), hgs_part_ = (part);                  \
    try {                                                                                                    \
      statement;                                                                                             \
      ADD_FAILURE() << #statement " did not throw";                                                          \
    } catch (const ::hgs::Error& e) {                                                                        \
      const std::string m = e.what();                                                                        \
      EXPECT_NE(m.find(hgs_file_), std::string::npos) << "message does not name " << hgs_file_ << ": " << m; \
      EXPECT_EQ(m.find('\n'), std::string::npos) << "message is not one line: " << m;                        \
      EXPECT_NE(m.find(hgs_part_), std::string::npos) << "message lacks \"" << hgs_part_ << "\": " << m;     \
    }                                                                                                        \
  } while (0)
