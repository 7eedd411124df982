// libFuzzer target for the two configuration files of a dense workspace:
// every input is parsed both as stereo/patch-match.cfg and as
// stereo/fusion.cfg (the formats share their line rules, so one corpus feeds
// both).
//
// Properties checked, besides "no crash, no sanitizer report":
//  * the parsers throw nothing but IoError;
//  * what they accept, the writers write (or refuse with IoError, but only for
//    the names their documentation says cannot be written: ones with a line
//    break, a leading '#' or a leading byte order mark), and parsing that file
//    gives the same entries and writing them again the same bytes (a stable
//    round trip).

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "colmap_io/error.h"
#include "colmap_io/stereo_config.h"
#include "tests/fuzz/fuzz_support.h"

namespace {

using dispmvs::colmap_io::IoError;
using dispmvs::colmap_io::PatchMatchEntry;
using dispmvs::colmap_io::SourceSpec;

// Names the writers document as unwritable that the parsers can still yield:
// a carriage return inside a name, a leading '#' (in a source list, after the
// first name) and a leading UTF-8 byte order mark (anywhere but at the very
// start of the file).
bool DocumentedUnwritable(const std::string& name) {
  return name.find('\r') != std::string::npos || (!name.empty() && name[0] == '#') ||
         name.compare(0, 3, "\xEF\xBB\xBF") == 0;
}

bool AnyDocumentedUnwritable(const std::vector<PatchMatchEntry>& entries) {
  for (const PatchMatchEntry& entry : entries) {
    if (DocumentedUnwritable(entry.reference)) return true;
    for (const std::string& name : entry.sources.names) {
      if (DocumentedUnwritable(name)) return true;
    }
  }
  return false;
}

bool AnyDocumentedUnwritable(const std::vector<std::string>& names) {
  for (const std::string& name : names) {
    if (DocumentedUnwritable(name)) return true;
  }
  return false;
}

// What every accepted entry must satisfy (stereo_config.h).
void CheckEntries(const std::vector<PatchMatchEntry>& entries) {
  for (const PatchMatchEntry& entry : entries) {
    if (entry.reference.empty()) std::abort();
    const SourceSpec& spec = entry.sources;
    switch (spec.kind) {
      case SourceSpec::Kind::kAuto:
        if (spec.max_num_sources < 1 ||
            spec.max_num_sources > dispmvs::colmap_io::kMaxAutoSources || !spec.names.empty()) {
          std::abort();
        }
        break;
      case SourceSpec::Kind::kAll:
        if (spec.max_num_sources != 0 || !spec.names.empty()) std::abort();
        break;
      case SourceSpec::Kind::kExplicit:
        if (spec.names.empty()) std::abort();
        for (const std::string& name : spec.names) {
          if (name.empty() || name == entry.reference) std::abort();
        }
        break;
    }
  }
}

template <typename Parse>
auto ParseBytes(Parse parse, const std::string& bytes) {
  std::istringstream in(bytes);
  return parse(in, "fuzz-input");
}

// Parse -> Write -> Parse -> Write for one of the two formats. `Entries` is
// std::vector<PatchMatchEntry> or std::vector<std::string>.
template <typename Entries, typename Parse, typename Write>
void CheckFormat(const std::string& input, const char* file_name, Parse parse, Write write) {
  Entries entries;
  try {
    entries = ParseBytes(parse, input);
  } catch (const IoError&) {
    return;  // rejected cleanly
  }
  const auto path = dispmvs::fuzz::ScratchPath(file_name);
  try {
    write(entries, path);
  } catch (const IoError&) {
    if (AnyDocumentedUnwritable(entries)) return;
    std::abort();  // the writer refused something it documents as writable
  }
  const std::string first = dispmvs::fuzz::ReadBytes(path);
  Entries again;
  try {
    again = ParseBytes(parse, first);
  } catch (const IoError&) {
    std::abort();  // the parser refused what the writer wrote
  }
  if (again != entries) std::abort();
  write(again, path);
  if (dispmvs::fuzz::ReadBytes(path) != first) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);

  CheckFormat<std::vector<PatchMatchEntry>>(
      input, "patch-match.cfg",
      [](std::istream& in, const std::string& name) {
        std::vector<PatchMatchEntry> entries = dispmvs::colmap_io::ParsePatchMatchConfig(in, name);
        CheckEntries(entries);
        return entries;
      },
      dispmvs::colmap_io::WritePatchMatchConfig);

  CheckFormat<std::vector<std::string>>(
      input, "fusion.cfg",
      [](std::istream& in, const std::string& name) {
        std::vector<std::string> names = dispmvs::colmap_io::ParseFusionConfig(in, name);
        for (const std::string& n : names) {
          if (n.empty()) std::abort();
        }
        return names;
      },
      dispmvs::colmap_io::WriteFusionConfig);
  return 0;
}
