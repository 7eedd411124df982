#pragma once
// Private to colmap_io: bounded little-endian reads from a seekable stream.
// The number of bytes left is measured once up front, so every read and every
// count can be checked against it BEFORE anything is read or allocated: a
// corrupt count of 2^60 fails at once instead of exhausting memory.
// Errors name the source and the record being read (kept lazily as
// kind/index/id and only formatted when an error is thrown).

#include <cstdint>
#include <cstring>
#include <istream>
#include <limits>
#include <string>
#include <type_traits>

#include "colmap_io/error.h"

namespace dispmvs::colmap_io::internal {

class BinaryReader {
 public:
  BinaryReader(std::istream& in, std::string source_name)
      : in_(in), source_name_(std::move(source_name)) {
    const std::streampos start = in_.tellg();
    in_.seekg(0, std::ios::end);
    const std::streampos end = in_.tellg();
    in_.seekg(start);
    if (start < 0 || end < 0 || !in_) {
      throw IoError(source_name_, "cannot determine the size of the input (not seekable?)");
    }
    remaining_ = static_cast<uint64_t>(end - start);
  }

  uint64_t remaining() const { return remaining_; }

  // Names the record being read in later error messages, e.g. "image #3";
  // SetRecordId adds "(image_id 7)" once the id is known.
  void SetRecord(const char* kind, uint64_t index) {
    record_kind_ = kind;
    record_index_ = index;
    has_record_id_ = false;
  }
  void SetRecordId(const char* id_name, uint64_t id) {
    record_id_name_ = id_name;
    record_id_ = id;
    has_record_id_ = true;
  }

  [[noreturn]] void Fail(const std::string& what) const {
    std::string message;
    if (record_kind_ != nullptr) {
      message = std::string(record_kind_) + " #" + std::to_string(record_index_);
      if (has_record_id_) {
        message += " (" + std::string(record_id_name_) + " " + std::to_string(record_id_) + ")";
      }
      message += ": ";
    }
    throw IoError(source_name_, message + what);
  }

  // Reads an unsigned or signed integer of sizeof(T) bytes, little endian.
  template <typename T>
  T ReadInt(const char* field) {
    static_assert(std::is_integral_v<T>);
    unsigned char bytes[sizeof(T)];
    ReadBytes(bytes, sizeof(T), field);
    using U = std::make_unsigned_t<T>;
    U value = 0;
    for (size_t i = 0; i < sizeof(T); ++i)
      value |= static_cast<U>(static_cast<U>(bytes[i]) << (8 * i));
    return static_cast<T>(value);
  }

  double ReadDouble(const char* field) {
    const uint64_t bits = ReadInt<uint64_t>(field);
    double value;
    std::memcpy(&value, &bits, sizeof(value));
    return value;
  }

  // A NUL-terminated string; the terminator must lie within the remaining bytes.
  std::string ReadNulTerminated(const char* field) {
    std::string value;
    std::getline(in_, value, '\0');
    // getline stops at the NUL (consumed, not stored) or at the end of the
    // stream; only the first case is a complete string.
    const bool terminated = !in_.eof() && in_.good();
    if (!terminated || value.size() + 1 > remaining_) {
      Fail(std::string(field) + ": no terminating NUL byte before the end of the data");
    }
    remaining_ -= value.size() + 1;
    return value;
  }

  // A count of records that each take at least `min_record_bytes`; fails
  // unless that many could still fit in what is left, so callers may then
  // reserve `count` elements safely.
  uint64_t ReadCount(const char* field, uint64_t min_record_bytes) {
    const uint64_t count = ReadInt<uint64_t>(field);
    if (count > remaining_ / min_record_bytes) {
      Fail(std::string(field) + " is " + std::to_string(count) + " but only " +
           std::to_string(remaining_) + " bytes remain (at least " +
           std::to_string(min_record_bytes) + " per entry): wrong count or truncated file");
    }
    return count;
  }

  // After the last declared record: leftover bytes mean the count was wrong.
  void ExpectEnd(uint64_t declared_count) {
    if (remaining_ != 0) {
      record_kind_ = nullptr;
      Fail(std::to_string(remaining_) + " unexpected bytes after the " +
           std::to_string(declared_count) + " records the header declares (wrong count?)");
    }
  }

 private:
  void ReadBytes(unsigned char* out, size_t size, const char* field) {
    if (size > remaining_) {
      Fail(std::string("truncated data: ") + field + " needs " + std::to_string(size) +
           " bytes but only " + std::to_string(remaining_) + " remain");
    }
    in_.read(reinterpret_cast<char*>(out), static_cast<std::streamsize>(size));
    if (!in_) Fail(std::string("read error in ") + field);
    remaining_ -= size;
  }

  std::istream& in_;
  std::string source_name_;
  uint64_t remaining_ = 0;
  const char* record_kind_ = nullptr;
  uint64_t record_index_ = 0;
  const char* record_id_name_ = "";
  uint64_t record_id_ = 0;
  bool has_record_id_ = false;
};

}  // namespace dispmvs::colmap_io::internal
