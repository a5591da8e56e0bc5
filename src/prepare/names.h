// Photo file names as the input stage gives them to COLMAP. COLMAP reads image lists line by line with the
// surrounding white space trimmed and cannot carry a name with a backslash (a Windows-made archive unzipped on
// Linux gives "dir\photo.jpg"), a control character (tab, newline) or leading / trailing spaces: such a photo is
// silently left out of mapping. Names that are not UTF-8 (Latin-1 names of an old archive) cannot go into the
// JSON records of hgs (nor its reports): they are made safe the same way. The input stage writes it under a safe name
// instead (each such byte becomes '_') and lists the renaming in its report; the source keeps its name.
#pragma once
#include <filesystem>
#include <string>

namespace hgs::prepare {

// `name` with every byte COLMAP cannot carry (backslash, bytes 0x00-0x1F and 0x7F, leading or trailing spaces)
// and every byte outside a valid UTF-8 sequence replaced by '_'; `name` itself when it has none.
std::string colmap_safe_name(const std::string& name);

// True when the file name ends in .jpg, .jpeg, .jpe or .png (any case): what a photo copy is named.
bool has_image_extension(const std::filesystem::path& path);

}  // namespace hgs::prepare
