#include "colmap_io/stereo_config.h"

#include <fstream>
#include <map>
#include <set>
#include <stdexcept>
#include <system_error>
#include <utility>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"

namespace dispmvs::colmap_io {
namespace {

constexpr const char* kAutoKeyword = "__auto__";
constexpr const char* kAllKeyword = "__all__";
constexpr const char* kWhitespace = " \t\r\n\v\f";
// The UTF-8 byte order mark, dropped from the start of a file by the readers.
constexpr const char* kUtf8Bom = "\xEF\xBB\xBF";

std::string Trim(const std::string& text) {
  const std::size_t begin = text.find_first_not_of(kWhitespace);
  if (begin == std::string::npos) return "";
  const std::size_t end = text.find_last_not_of(kWhitespace);
  return text.substr(begin, end - begin + 1);
}

// A meaningful line of a config file, with its 1-based line number for error
// messages.
struct ConfigLine {
  std::size_t number = 0;
  std::string text;
};

// The trimmed lines that are neither blank nor comments. A UTF-8 byte order
// mark (which Windows editors like to add) is dropped from the first line.
std::vector<ConfigLine> ReadMeaningfulLines(std::istream& in) {
  std::vector<ConfigLine> lines;
  std::string line;
  std::size_t number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (number == 1 && line.compare(0, 3, kUtf8Bom) == 0) line.erase(0, 3);
    std::string text = Trim(line);
    if (text.empty() || text[0] == '#') continue;
    lines.push_back({number, std::move(text)});
  }
  return lines;
}

std::string LineLabel(std::size_t number) { return "line " + std::to_string(number) + ": "; }

std::vector<std::string> SplitAndTrim(const std::string& text, char separator) {
  std::vector<std::string> fields;
  std::size_t begin = 0;
  while (true) {
    const std::size_t end = text.find(separator, begin);
    fields.push_back(Trim(text.substr(begin, end == std::string::npos ? end : end - begin)));
    if (end == std::string::npos) break;
    begin = end + 1;
  }
  return fields;
}

bool IsKeyword(const std::string& field) { return field == kAutoKeyword || field == kAllKeyword; }

// Parses the N of "__auto__, N": plain decimal digits, 1..kMaxAutoSources.
std::size_t ParseAutoCount(const std::string& field, const ConfigLine& line,
                           const std::string& source_name) {
  const std::string usage = " (expected \"__auto__, N\" with N a positive integer)";
  if (field.empty() || field.find_first_not_of("0123456789") != std::string::npos) {
    throw IoError(source_name,
                  LineLabel(line.number) + "\"" + field + "\" is not a number of images" + usage);
  }
  // Digits only, so this cannot go negative; stop before it can overflow.
  std::size_t value = 0;
  for (char digit : field) {
    value = value * 10 + static_cast<std::size_t>(digit - '0');
    if (value > kMaxAutoSources) {
      throw IoError(source_name, LineLabel(line.number) + "__auto__ count " + field +
                                     " is too large (at most " +
                                     std::to_string(kMaxAutoSources) + ")");
    }
  }
  if (value == 0) {
    throw IoError(source_name, LineLabel(line.number) + "__auto__ count must be at least 1" + usage);
  }
  return value;
}

SourceSpec ParseSourcesLine(const ConfigLine& line, const std::string& reference,
                            const std::string& source_name) {
  const std::vector<std::string> fields = SplitAndTrim(line.text, ',');
  if (fields[0] == kAutoKeyword) {
    if (fields.size() != 2) {
      throw IoError(source_name, LineLabel(line.number) + "\"" + line.text +
                                     "\": expected \"__auto__, N\" with N a positive integer");
    }
    return SourceSpec::Auto(ParseAutoCount(fields[1], line, source_name));
  }
  if (fields[0] == kAllKeyword) {
    if (fields.size() != 1) {
      throw IoError(source_name,
                    LineLabel(line.number) + "\"__all__\" must stand alone on its line");
    }
    return SourceSpec::All();
  }
  std::set<std::string> seen;
  for (const std::string& name : fields) {
    if (name.empty()) {
      throw IoError(source_name, LineLabel(line.number) + "empty image name in the sources of \"" +
                                     reference + "\"");
    }
    if (IsKeyword(name)) {
      throw IoError(source_name, LineLabel(line.number) + "\"" + name +
                                     "\" is a keyword and can only begin a sources line");
    }
    if (name == reference) {
      throw IoError(source_name, LineLabel(line.number) + "\"" + reference +
                                     "\" lists itself as a source image");
    }
    if (!seen.insert(name).second) {
      throw IoError(source_name, LineLabel(line.number) + "source image \"" + name +
                                     "\" listed twice");
    }
  }
  return SourceSpec::Explicit(fields);
}

// Rejects reference names that are really sources lines: the usual sign of a
// missing line, which would otherwise shift every following pair.
void CheckReferenceName(const ConfigLine& line, const std::string& source_name) {
  const std::vector<std::string> fields = SplitAndTrim(line.text, ',');
  if (fields.size() > 1 || IsKeyword(fields[0])) {
    throw IoError(source_name, LineLabel(line.number) + "expected a reference image name, found \"" +
                                   line.text +
                                   "\" (a sources line; is a reference line missing above?)");
  }
}

// Why `name` would not survive a write/read round trip, or "" if it would.
std::string UnwritableNameReason(const std::string& name, bool in_comma_list) {
  if (name.empty()) return "empty image name";
  if (name.find_first_of("\r\n") != std::string::npos) return "image name contains a line break";
  if (Trim(name) != name) return "image name has leading or trailing whitespace";
  if (name[0] == '#') return "image name starts with '#' (would read back as a comment)";
  // On the first line the readers would drop the mark and read another name
  // (or a comment, or nothing). Refused wherever it is, like '#'.
  if (name.compare(0, 3, kUtf8Bom) == 0) {
    return "image name starts with a UTF-8 byte order mark (would read back without it)";
  }
  if (in_comma_list && name.find(',') != std::string::npos) {
    return "image name contains ',' (patch-match.cfg separates names with commas)";
  }
  if (in_comma_list && IsKeyword(name)) return "image name is a patch-match.cfg keyword";
  return "";
}

void CheckWritableName(const std::string& name, bool in_comma_list,
                       const std::filesystem::path& path) {
  const std::string reason = UnwritableNameReason(name, in_comma_list);
  if (!reason.empty()) throw IoError(path.string(), "cannot write \"" + name + "\": " + reason);
}

std::ifstream OpenConfig(const std::filesystem::path& path) {
  // A directory opens as an ifstream on Linux and reads as empty: it would
  // pass for a config without entries.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw IoError(path.string(), "is a directory");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open for reading");
  return in;
}

}  // namespace

SourceSpec SourceSpec::Auto(std::size_t max_num_sources) {
  SourceSpec spec;
  spec.kind = Kind::kAuto;
  spec.max_num_sources = max_num_sources;
  return spec;
}

SourceSpec SourceSpec::All() { return SourceSpec(); }

SourceSpec SourceSpec::Explicit(std::vector<std::string> names) {
  SourceSpec spec;
  spec.kind = Kind::kExplicit;
  spec.names = std::move(names);
  return spec;
}

bool SourceSpec::operator==(const SourceSpec& other) const {
  return kind == other.kind && max_num_sources == other.max_num_sources && names == other.names;
}

std::vector<PatchMatchEntry> ParsePatchMatchConfig(std::istream& in,
                                                   const std::string& source_name) {
  const std::vector<ConfigLine> lines = ReadMeaningfulLines(in);
  std::vector<PatchMatchEntry> entries;
  std::map<std::string, std::size_t> reference_lines;
  for (std::size_t i = 0; i < lines.size(); i += 2) {
    const ConfigLine& reference_line = lines[i];
    CheckReferenceName(reference_line, source_name);
    if (i + 1 == lines.size()) {
      throw IoError(source_name, LineLabel(reference_line.number) + "reference image \"" +
                                     reference_line.text + "\" has no sources line after it");
    }
    const auto [previous, inserted] =
        reference_lines.emplace(reference_line.text, reference_line.number);
    if (!inserted) {
      throw IoError(source_name, LineLabel(reference_line.number) + "reference image \"" +
                                     reference_line.text + "\" already configured on line " +
                                     std::to_string(previous->second));
    }
    entries.push_back(
        {reference_line.text, ParseSourcesLine(lines[i + 1], reference_line.text, source_name)});
  }
  return entries;
}

std::vector<PatchMatchEntry> ReadPatchMatchConfig(const std::filesystem::path& path) {
  std::ifstream in = OpenConfig(path);
  return ParsePatchMatchConfig(in, path.string());
}

void WritePatchMatchConfig(const std::vector<PatchMatchEntry>& entries,
                           const std::filesystem::path& path) {
  // Validate everything before creating the file.
  std::set<std::string> references;
  for (const PatchMatchEntry& entry : entries) {
    CheckWritableName(entry.reference, /*in_comma_list=*/true, path);
    if (!references.insert(entry.reference).second) {
      throw IoError(path.string(), "reference image \"" + entry.reference + "\" appears twice");
    }
    const SourceSpec& spec = entry.sources;
    if (spec.kind == SourceSpec::Kind::kAuto &&
        (spec.max_num_sources == 0 || spec.max_num_sources > kMaxAutoSources)) {
      throw IoError(path.string(), "invalid __auto__ count " +
                                       std::to_string(spec.max_num_sources) + " for \"" +
                                       entry.reference + "\"");
    }
    if (spec.kind == SourceSpec::Kind::kExplicit) {
      if (spec.names.empty()) {
        throw IoError(path.string(), "no source images for \"" + entry.reference + "\"");
      }
      for (const std::string& name : spec.names) CheckWritableName(name, true, path);
    }
  }
  WriteFileAtomically(path, [&](std::ostream& out) {
    for (const PatchMatchEntry& entry : entries) {
      out << entry.reference << '\n';
      switch (entry.sources.kind) {
        case SourceSpec::Kind::kAuto:
          out << kAutoKeyword << ", " << std::to_string(entry.sources.max_num_sources) << '\n';
          break;
        case SourceSpec::Kind::kAll:
          out << kAllKeyword << '\n';
          break;
        case SourceSpec::Kind::kExplicit:
          for (std::size_t i = 0; i < entry.sources.names.size(); ++i) {
            out << (i == 0 ? "" : ", ") << entry.sources.names[i];
          }
          out << '\n';
          break;
      }
    }
  });
}

std::vector<std::string> ParseFusionConfig(std::istream& in, const std::string& source_name) {
  std::vector<std::string> names;
  std::map<std::string, std::size_t> first_lines;
  for (ConfigLine& line : ReadMeaningfulLines(in)) {
    const auto [previous, inserted] = first_lines.emplace(line.text, line.number);
    if (!inserted) {
      throw IoError(source_name, LineLabel(line.number) + "image \"" + line.text +
                                     "\" already listed on line " +
                                     std::to_string(previous->second));
    }
    names.push_back(std::move(line.text));
  }
  return names;
}

std::vector<std::string> ReadFusionConfig(const std::filesystem::path& path) {
  std::ifstream in = OpenConfig(path);
  return ParseFusionConfig(in, path.string());
}

void WriteFusionConfig(const std::vector<std::string>& names, const std::filesystem::path& path) {
  std::set<std::string> seen;
  for (const std::string& name : names) {
    CheckWritableName(name, /*in_comma_list=*/false, path);
    if (!seen.insert(name).second) {
      throw IoError(path.string(), "image \"" + name + "\" appears twice");
    }
  }
  WriteFileAtomically(path, [&](std::ostream& out) {
    for (const std::string& name : names) out << name << '\n';
  });
}

std::vector<image_t> ResolveSourceImages(const SourceSpec& spec, image_t reference_image_id,
                                         const SparseModel& model,
                                         const ViewSelectionOptions& view_selection,
                                         const std::string& config_name) {
  const auto reference = model.images.find(reference_image_id);
  if (reference == model.images.end()) {
    throw std::invalid_argument("ResolveSourceImages: reference image id " +
                                std::to_string(reference_image_id) + " is not in the model");
  }
  std::vector<image_t> sources;
  switch (spec.kind) {
    case SourceSpec::Kind::kAuto:
      return SelectSourceViews(model, reference_image_id, spec.max_num_sources, view_selection);
    case SourceSpec::Kind::kAll:
      for (const auto& [image_id, image] : model.images) {
        if (image_id != reference_image_id) sources.push_back(image_id);
      }
      return sources;
    case SourceSpec::Kind::kExplicit:
      for (const std::string& name : spec.names) {
        const Image* image = model.FindImageByName(name);
        if (image == nullptr) {
          throw IoError(config_name, "source image \"" + name + "\" of \"" +
                                         reference->second.name +
                                         "\" is not an image of the sparse model");
        }
        if (image->image_id == reference_image_id) {
          throw IoError(config_name, "\"" + name + "\" lists itself as a source image");
        }
        sources.push_back(image->image_id);
      }
      return sources;
  }
  return sources;
}

std::vector<StereoProblem> ResolvePatchMatchConfig(const std::vector<PatchMatchEntry>& entries,
                                                   const SparseModel& model,
                                                   const ViewSelectionOptions& view_selection,
                                                   const std::string& config_name) {
  std::vector<StereoProblem> problems;
  problems.reserve(entries.size());
  for (const PatchMatchEntry& entry : entries) {
    const Image* reference = model.FindImageByName(entry.reference);
    if (reference == nullptr) {
      throw IoError(config_name, "reference image \"" + entry.reference +
                                     "\" is not an image of the sparse model");
    }
    problems.push_back({reference->image_id,
                        ResolveSourceImages(entry.sources, reference->image_id, model,
                                            view_selection, config_name)});
  }
  return problems;
}

std::vector<StereoProblem> ResolvePatchMatchConfigWithPoseFallback(
    const std::vector<PatchMatchEntry>& entries, const SparseModel& model,
    const ViewSelectionOptions& view_selection, const std::string& config_name,
    const SampleDepthsFunction& sample_depths, std::set<image_t>* pose_selected) {
  std::vector<StereoProblem> problems =
      ResolvePatchMatchConfig(entries, model, view_selection, config_name);
  // ResolvePatchMatchConfig gives one problem per entry, in order.
  for (std::size_t i = 0; i < entries.size(); ++i) {
    StereoProblem& problem = problems[i];
    if (entries[i].sources.kind != SourceSpec::Kind::kAuto ||
        SharesSparsePoints(model, problem.reference_image_id)) {
      continue;
    }
    if (pose_selected != nullptr) pose_selected->insert(problem.reference_image_id);
    const auto depths = sample_depths(problem.reference_image_id);
    problem.source_image_ids =
        depths ? SelectSourceViewsByPose(model, problem.reference_image_id,
                                         entries[i].sources.max_num_sources, depths->first,
                                         depths->second, view_selection)
               : std::vector<image_t>{};
  }
  return problems;
}

std::vector<PatchMatchEntry> AutoPatchMatchConfig(const SparseModel& model,
                                                  std::size_t max_num_sources) {
  if (max_num_sources == 0) {
    throw std::invalid_argument("AutoPatchMatchConfig: max_num_sources must be at least 1");
  }
  std::vector<PatchMatchEntry> entries;
  entries.reserve(model.images.size());
  for (const auto& [image_id, image] : model.images) {
    entries.push_back({image.name, SourceSpec::Auto(max_num_sources)});
  }
  return entries;
}

void CapAutoSources(std::size_t max_num_sources, std::vector<PatchMatchEntry>* entries) {
  for (PatchMatchEntry& entry : *entries) {
    if (entry.sources.kind == SourceSpec::Kind::kAuto) {
      entry.sources.max_num_sources = std::min(entry.sources.max_num_sources, max_num_sources);
    }
  }
}

}  // namespace dispmvs::colmap_io
