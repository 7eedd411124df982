#include "bench/npy_reader.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <system_error>

#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"

namespace dispmvs::bench {
namespace {

using colmap_io::IoError;

constexpr char kMagic[] = "\x93NUMPY";
constexpr std::size_t kMagicSize = 6;

uint64_t LittleEndian(const std::string& bytes, std::size_t offset, int size) {
  uint64_t value = 0;
  for (int i = size - 1; i >= 0; --i) {
    value = (value << 8) | static_cast<unsigned char>(bytes[offset + static_cast<std::size_t>(i)]);
  }
  return value;
}

// Shows a header fragment in an error message without control characters.
std::string Printable(const std::string& text) {
  std::string out;
  for (const char c : text) out += (c >= 0x20 && c < 0x7f) ? c : '?';
  return out;
}

// The dict literal of the header: {'key': value, ...}. Only the value forms
// numpy writes are understood: a quoted string, True/False, a tuple of
// non-negative integers.
class HeaderParser {
 public:
  HeaderParser(const std::string& text, const std::string& source_name)
      : text_(text), source_name_(source_name) {}

  struct Header {
    std::string descr;
    bool fortran_order = false;
    std::vector<uint64_t> shape;
  };

  Header Parse() {
    Header header;
    bool have_descr = false, have_order = false, have_shape = false;
    SkipSpaces();
    Expect('{');
    for (;;) {
      SkipSpaces();
      if (Peek() == '}') break;
      const std::string key = QuotedString();
      SkipSpaces();
      Expect(':');
      SkipSpaces();
      if (key == "descr") {
        if (have_descr) Fail("key 'descr' appears twice");
        header.descr = QuotedString();
        have_descr = true;
      } else if (key == "fortran_order") {
        if (have_order) Fail("key 'fortran_order' appears twice");
        header.fortran_order = Boolean();
        have_order = true;
      } else if (key == "shape") {
        if (have_shape) Fail("key 'shape' appears twice");
        header.shape = Tuple();
        have_shape = true;
      } else {
        Fail("unknown key '" + Printable(key) + "' (expected descr, fortran_order, shape)");
      }
      SkipSpaces();
      if (Peek() == ',') {
        ++at_;
        continue;
      }
      if (Peek() != '}') Fail("expected ',' or '}'");
    }
    ++at_;  // '}'
    // numpy pads with spaces up to the '\n' that ends the header.
    while (at_ < text_.size() && text_[at_] == ' ') ++at_;
    if (at_ + 1 != text_.size() || text_[at_] != '\n') {
      Fail("the header must end with spaces and a newline after the dict");
    }
    if (!have_descr) Fail("key 'descr' is missing");
    if (!have_order) Fail("key 'fortran_order' is missing");
    if (!have_shape) Fail("key 'shape' is missing");
    return header;
  }

 private:
  [[noreturn]] void Fail(const std::string& what) const {
    throw IoError(source_name_, "bad NPY header \"" + Printable(text_) + "\": " + what +
                                    " (at character " + std::to_string(at_) + ")");
  }
  char Peek() const { return at_ < text_.size() ? text_[at_] : '\0'; }
  void SkipSpaces() {
    while (at_ < text_.size() && text_[at_] == ' ') ++at_;
  }
  void Expect(char c) {
    if (Peek() != c) Fail(std::string("expected '") + c + "'");
    ++at_;
  }
  std::string QuotedString() {
    const char quote = Peek();
    if (quote != '\'' && quote != '"') Fail("expected a quoted string");
    const std::size_t end = text_.find(quote, at_ + 1);
    if (end == std::string::npos) Fail("unterminated string");
    std::string value = text_.substr(at_ + 1, end - at_ - 1);
    if (value.find('\\') != std::string::npos) Fail("escapes in strings are not supported");
    at_ = end + 1;
    return value;
  }
  bool Boolean() {
    if (text_.compare(at_, 4, "True") == 0) {
      at_ += 4;
      return true;
    }
    if (text_.compare(at_, 5, "False") == 0) {
      at_ += 5;
      return false;
    }
    Fail("expected True or False");
  }
  std::vector<uint64_t> Tuple() {
    Expect('(');
    std::vector<uint64_t> values;
    for (;;) {
      SkipSpaces();
      if (Peek() == ')') break;
      if (Peek() < '0' || Peek() > '9') Fail("expected a non-negative integer in the shape");
      uint64_t value = 0;
      while (Peek() >= '0' && Peek() <= '9') {
        if (value > (std::numeric_limits<uint64_t>::max() - 9) / 10) Fail("shape entry too large");
        value = value * 10 + static_cast<uint64_t>(Peek() - '0');
        ++at_;
      }
      values.push_back(value);
      SkipSpaces();
      if (Peek() == ',') {
        ++at_;
        continue;
      }
      if (Peek() != ')') Fail("expected ',' or ')' in the shape");
    }
    ++at_;  // ')'
    return values;
  }

  const std::string& text_;
  const std::string& source_name_;
  std::size_t at_ = 0;
};

std::string ShapeText(const std::vector<uint64_t>& shape) {
  std::string text = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    text += (i > 0 ? ", " : "") + std::to_string(shape[i]);
  }
  return text + (shape.size() == 1 ? ",)" : ")");
}

}  // namespace

NpyMatrix ParseNpyMatrix(const std::string& bytes, const std::string& source_name) {
  if (bytes.size() < kMagicSize + 2 || bytes.compare(0, kMagicSize, kMagic, kMagicSize) != 0) {
    throw IoError(source_name, "not a NumPy .npy file (no \\x93NUMPY magic)");
  }
  const int major = static_cast<unsigned char>(bytes[6]);
  const int minor = static_cast<unsigned char>(bytes[7]);
  if (!((major == 1 || major == 2) && minor == 0)) {
    throw IoError(source_name, "NPY format version " + std::to_string(major) + "." +
                                   std::to_string(minor) +
                                   " is not supported (1.0 and 2.0 are)");
  }
  const int length_size = major == 1 ? 2 : 4;
  const std::size_t header_start = kMagicSize + 2 + static_cast<std::size_t>(length_size);
  if (bytes.size() < header_start) throw IoError(source_name, "truncated NPY preamble");
  const uint64_t header_length = LittleEndian(bytes, kMagicSize + 2, length_size);
  if (header_length > bytes.size() - header_start) {
    throw IoError(source_name, "truncated NPY header: " + std::to_string(header_length) +
                                   " bytes announced, " +
                                   std::to_string(bytes.size() - header_start) + " in the file");
  }
  const std::string header_text = bytes.substr(header_start, header_length);
  const HeaderParser::Header header = HeaderParser(header_text, source_name).Parse();

  int value_size = 0;
  if (header.descr == "<f4") {
    value_size = 4;
  } else if (header.descr == "<f8") {
    value_size = 8;
  } else if (header.descr == ">f4" || header.descr == ">f8") {
    throw IoError(source_name, "dtype '" + header.descr +
                                   "' is big-endian; save it as little-endian ('<f4' or '<f8')");
  } else {
    throw IoError(source_name, "dtype '" + Printable(header.descr) +
                                   "' is not supported: expected '<f4' or '<f8' (float32 / "
                                   "float64, little-endian)");
  }
  if (header.fortran_order) {
    throw IoError(source_name,
                  "Fortran-order (column-major) arrays are not supported: save a C-order array");
  }
  if (header.shape.size() != 2) {
    throw IoError(source_name, "shape " + ShapeText(header.shape) + " is not 2-D (rows, cols)");
  }
  for (const uint64_t side : header.shape) {
    if (side < 1 || side > colmap_io::kMaxDenseArraySide) {
      throw IoError(source_name, "shape " + ShapeText(header.shape) + ": each side must be in [1, " +
                                     std::to_string(colmap_io::kMaxDenseArraySide) + "]");
    }
  }
  const uint64_t count = header.shape[0] * header.shape[1];
  const uint64_t expected = count * static_cast<uint64_t>(value_size);
  const std::size_t data_start = header_start + header_length;
  const uint64_t present = bytes.size() - data_start;
  if (present != expected) {
    throw IoError(source_name, std::string(present < expected ? "truncated" : "trailing data") +
                                   ": shape " + ShapeText(header.shape) + " of '" + header.descr +
                                   "' needs " + std::to_string(expected) + " bytes of data, " +
                                   "the file has " + std::to_string(present));
  }

  NpyMatrix matrix;
  matrix.rows = static_cast<int>(header.shape[0]);
  matrix.cols = static_cast<int>(header.shape[1]);
  matrix.descr = header.descr;
  matrix.values.resize(static_cast<std::size_t>(count));
  for (std::size_t i = 0; i < matrix.values.size(); ++i) {
    const uint64_t bits = LittleEndian(bytes, data_start + i * value_size, value_size);
    if (value_size == 4) {
      const uint32_t bits32 = static_cast<uint32_t>(bits);
      float value;
      std::memcpy(&value, &bits32, sizeof value);
      matrix.values[i] = value;
    } else {
      double value;
      std::memcpy(&value, &bits, sizeof value);
      matrix.values[i] = value;
    }
  }
  return matrix;
}

NpyMatrix ReadNpyMatrix(const std::filesystem::path& path) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) throw IoError(path.string(), "no such file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open for reading");
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw IoError(path.string(), "read failed");
  return ParseNpyMatrix(bytes, path.string());
}

}  // namespace dispmvs::bench
