#pragma once
// What the photometric pass of dispmvs_colmap records about each view it
// computed, beside the view's maps, for the run report (eval/html_report.h):
//
//   WS/stereo/dispmvs_records/NAME.txt
//
// as "key value" lines:
//   seconds 1.234     wall time of the view: reading its images, the network
//                     and writing its maps
//   size 640x480      the maps' size
//   sources 4         source views used
//   device cpu        where the network ran
//
// or, for a view that failed (no maps written), the one line
//   failed REASON     the error, naming the file at fault
// so that the report and dispmvs_eval can say why a view has no map. A later
// run that computes the view replaces it.
//
// The file is written atomically after the maps; a view without one (computed
// before records existed, or killed between its maps and its record) simply
// has no time in the report. The times differ from run to run, so tests that
// compare runs byte for byte leave these files out.

#include <filesystem>
#include <optional>
#include <string>

#include "colmap_io/workspace.h"

namespace dispmvs::colmap_io {

struct ViewRecord {
  double seconds = 0;
  int width = 0, height = 0;
  int num_sources = 0;
  std::string device;
  // Not empty: the view failed for this reason and the other fields are unset.
  std::string failure;
};

// WS/stereo/dispmvs_records, the folder of every view's record.
std::filesystem::path ViewRecordFolder(const Workspace& workspace);
std::filesystem::path ViewRecordPath(const Workspace& workspace, const std::string& image_name);

// Atomically (colmap_io/atomic_file.h); throws IoError when it cannot.
void WriteViewRecord(const std::filesystem::path& path, const ViewRecord& record);

// nullopt when the file is absent or not a complete, valid record: a record
// only feeds the report, so a damaged one must not stop anything.
std::optional<ViewRecord> ReadViewRecord(const std::filesystem::path& path);

}  // namespace dispmvs::colmap_io
