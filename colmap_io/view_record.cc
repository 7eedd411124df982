#include "colmap_io/view_record.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include "colmap_io/atomic_file.h"

namespace dispmvs::colmap_io {

namespace fs = std::filesystem;

fs::path ViewRecordFolder(const Workspace& workspace) {
  return workspace.StereoDir() / "dispmvs_records";
}

fs::path ViewRecordPath(const Workspace& workspace, const std::string& image_name) {
  // DepthMapPath throws IoError for a name that would leave the workspace
  // ("..", an absolute path); the records follow the same rule.
  workspace.DepthMapPath(image_name, "record");
  return ViewRecordFolder(workspace) / (image_name + ".txt");
}

void WriteViewRecord(const fs::path& path, const ViewRecord& record) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    if (!record.failure.empty()) {  // one line: line breaks become spaces
      std::string reason = record.failure;
      for (char& c : reason) c = (c == '\n' || c == '\r') ? ' ' : c;
      out << "failed " << reason << '\n';
      return;
    }
    out.precision(6);
    out << "seconds " << std::fixed << record.seconds << '\n'
        << "size " << record.width << 'x' << record.height << '\n'
        << "sources " << record.num_sources << '\n'
        << "device " << record.device << '\n';
  });
}

std::optional<ViewRecord> ReadViewRecord(const fs::path& path) {
  std::ifstream in(path);
  if (!in) return std::nullopt;
  ViewRecord record;
  bool seconds = false, size = false, sources = false, device = false;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string key;
    fields >> key;
    if (key == "failed" && line.size() > 7) {
      record.failure = line.substr(7);
      return record;
    }
    if (key == "seconds") {
      seconds = static_cast<bool>(fields >> record.seconds) && std::isfinite(record.seconds) &&
                record.seconds >= 0;
    } else if (key == "size") {
      char x = 0;
      size = static_cast<bool>(fields >> record.width >> x >> record.height) && x == 'x' &&
             record.width > 0 && record.height > 0;
    } else if (key == "sources") {
      sources = static_cast<bool>(fields >> record.num_sources) && record.num_sources >= 0;
    } else if (key == "device") {
      device = static_cast<bool>(fields >> record.device);
    }
  }
  if (!(seconds && size && sources && device)) return std::nullopt;
  return record;
}

}  // namespace dispmvs::colmap_io
