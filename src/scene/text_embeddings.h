// The phrases side of a scene: LERF's canonical phrases, phrase files, and the writer of text_embeddings.json
// ({"phrase": [D floats], ...}; its reader is load_scene, scene.h).
#pragma once
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace hgs {

// LERF's canonical phrases, the negatives of its relevancy score (Kerr et al. 2023).
inline constexpr std::array<const char*, 4> kCanonicalPhrases = {"object", "things", "stuff", "texture"};

// A phrase file: one phrase a line; empty lines are skipped and a CRLF line ending is dropped.
std::vector<std::string> read_phrase_file(const std::filesystem::path& file);

// Sets te[phrases[i]] = embeddings[i * dim, (i + 1) * dim) for every phrase (replacing equal ones);
// embeddings [phrases.size(), dim].
void add_text_embeddings(nlohmann::json& te, const std::vector<std::string>& phrases,
                         const std::vector<float>& embeddings, int dim);

// Writes `te` ({"phrase": [D floats], ...}) to `file` atomically, on one line.
void write_text_embeddings(const std::filesystem::path& file, const nlohmann::json& te);

}  // namespace hgs
