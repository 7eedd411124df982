#include "fusion/fused_cloud_writer.h"

#include <unistd.h>

#include <limits>
#include <system_error>

#include "colmap_io/atomic_file.h"
#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "fusion/vis_file.h"

namespace dispmvs::fusion {

namespace fs = std::filesystem;

namespace {

constexpr std::size_t kFlushBytes = 1 << 20;

// Appends the body file at `path` to `out`.
void CopyBody(const fs::path& path, std::ostream& out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw colmap_io::IoError(path.string(), "cannot reopen for reading");
  out << in.rdbuf();
  if (in.bad()) throw colmap_io::IoError(path.string(), "read failed");
}

}  // namespace

FusedCloudWriter::FusedCloudWriter(const fs::path& ply_path)
    : ply_path_(ply_path),
      vis_path_(ply_path.string() + ".vis"),
      ply_body_path_(ply_path.string() + ".points.tmp-" + std::to_string(::getpid())),
      vis_body_path_(ply_path.string() + ".vis.points.tmp-" + std::to_string(::getpid())) {
  std::error_code error;
  if (ply_path.has_parent_path()) fs::create_directories(ply_path.parent_path(), error);
  ply_body_.open(ply_body_path_, std::ios::binary | std::ios::trunc);
  if (!ply_body_) throw colmap_io::IoError(ply_body_path_.string(), "cannot open for writing");
  vis_body_.open(vis_body_path_, std::ios::binary | std::ios::trunc);
  if (!vis_body_) throw colmap_io::IoError(vis_body_path_.string(), "cannot open for writing");
}

int FusedCloudWriter::RemoveLeftovers(const fs::path& ply_path) {
  // The body files are NAME.points.tmp-PID beside NAME and NAME.vis, so the
  // same removal of "X.tmp-*" covers them with X = NAME.points, NAME.vis.points.
  int removed = 0;
  for (const char* suffix : {"", ".vis", ".points", ".vis.points"}) {
    removed += colmap_io::RemoveLeftoverTemporaries(ply_path.string() + suffix);
  }
  return removed;
}

FusedCloudWriter::~FusedCloudWriter() {
  ply_body_.close();
  vis_body_.close();
  std::error_code ignored;
  fs::remove(ply_body_path_, ignored);
  fs::remove(vis_body_path_, ignored);
}

void FusedCloudWriter::Add(const FusedPoint& point) {
  colmap_io::PlyPoint record;
  const bool normal_finite = point.normal.allFinite();
  for (int c = 0; c < 3; ++c) {
    record.xyz[c] = point.xyz[c];
    record.normal[c] = normal_finite ? point.normal[c] : 0.0f;
  }
  record.rgb = point.rgb;
  colmap_io::AppendPlyRecord(record, &ply_buffer_);
  if (point.visibility.size() > std::numeric_limits<uint32_t>::max()) {
    throw colmap_io::IoError(vis_path_.string(), "a point has too many visible images");
  }
  AppendVisibilityRecord(point.visibility, &vis_buffer_);
  ++count_;
  if (ply_buffer_.size() + vis_buffer_.size() >= kFlushBytes) Flush();
}

void FusedCloudWriter::Flush() {
  ply_body_.write(ply_buffer_.data(), static_cast<std::streamsize>(ply_buffer_.size()));
  vis_body_.write(vis_buffer_.data(), static_cast<std::streamsize>(vis_buffer_.size()));
  ply_buffer_.clear();
  vis_buffer_.clear();
  if (!ply_body_) throw colmap_io::IoError(ply_body_path_.string(), "write failed (disk full?)");
  if (!vis_body_) throw colmap_io::IoError(vis_body_path_.string(), "write failed (disk full?)");
}

void FusedCloudWriter::Finish() {
  Flush();
  ply_body_.close();
  vis_body_.close();
  if (ply_body_.fail() || vis_body_.fail()) {
    throw colmap_io::IoError(ply_body_path_.string(), "write failed (disk full?)");
  }
  colmap_io::WriteFileAtomically(vis_path_, [&](std::ostream& out) {
    std::string count;
    AppendVisibilityHeader(count_, &count);
    out.write(count.data(), static_cast<std::streamsize>(count.size()));
    if (count_ > 0) CopyBody(vis_body_path_, out);
  });
  colmap_io::WriteFileAtomically(ply_path_, [&](std::ostream& out) {
    colmap_io::WritePlyHeader(count_, out);
    if (count_ > 0) CopyBody(ply_body_path_, out);
  });
}

}  // namespace dispmvs::fusion
