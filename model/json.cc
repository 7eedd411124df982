#include "model/json.h"

#include <stdexcept>
#include <unordered_set>

namespace dispmvs::model::json {
namespace {

// Deep enough for any safetensors header (depth 3), shallow enough that a
// hostile "[[[[..." cannot overflow the stack.
constexpr int kMaxDepth = 64;

class Parser {
 public:
  explicit Parser(const std::string& text) : text_(text) {}

  Value ParseDocument() {
    Value value = ParseValue(0);
    SkipWhitespace();
    if (pos_ != text_.size()) Fail("trailing characters");
    return value;
  }

 private:
  [[noreturn]] void Fail(const std::string& what) const {
    throw std::runtime_error("json: " + what + " at byte " + std::to_string(pos_));
  }

  void SkipWhitespace() {
    while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\t' ||
                                   text_[pos_] == '\n' || text_[pos_] == '\r')) {
      ++pos_;
    }
  }

  bool Consume(char c) {
    if (pos_ < text_.size() && text_[pos_] == c) {
      ++pos_;
      return true;
    }
    return false;
  }

  void Expect(char c) {
    if (!Consume(c)) Fail(std::string("expected '") + c + "'");
  }

  void ExpectWord(const char* word) {
    for (const char* p = word; *p != '\0'; ++p) {
      if (!Consume(*p)) Fail(std::string("expected '") + word + "'");
    }
  }

  Value ParseValue(int depth) {
    if (depth > kMaxDepth) Fail("nesting too deep");
    SkipWhitespace();
    if (pos_ >= text_.size()) Fail("unexpected end of input");
    Value value;
    const char c = text_[pos_];
    if (c == '{') {
      value.type = Value::Type::kObject;
      ParseObject(value, depth);
    } else if (c == '[') {
      value.type = Value::Type::kArray;
      ParseArray(value, depth);
    } else if (c == '"') {
      value.type = Value::Type::kString;
      value.text = ParseString();
    } else if (c == 't') {
      ExpectWord("true");
      value.type = Value::Type::kBool;
      value.boolean = true;
    } else if (c == 'f') {
      ExpectWord("false");
      value.type = Value::Type::kBool;
    } else if (c == 'n') {
      ExpectWord("null");
    } else if (c == '-' || (c >= '0' && c <= '9')) {
      value.type = Value::Type::kNumber;
      value.text = ParseNumber();
    } else {
      Fail(std::string("unexpected character '") + c + "'");
    }
    return value;
  }

  void ParseObject(Value& value, int depth) {
    Expect('{');
    SkipWhitespace();
    if (Consume('}')) return;
    // A set, not Value::Find, so a header with many keys stays linear.
    std::unordered_set<std::string> seen;
    while (true) {
      SkipWhitespace();
      if (pos_ >= text_.size() || text_[pos_] != '"') Fail("expected a string key");
      std::string key = ParseString();
      if (!seen.insert(key).second) Fail("duplicate key \"" + key + "\"");
      SkipWhitespace();
      Expect(':');
      value.object.emplace_back(std::move(key), ParseValue(depth + 1));
      SkipWhitespace();
      if (Consume('}')) return;
      Expect(',');
    }
  }

  void ParseArray(Value& value, int depth) {
    Expect('[');
    SkipWhitespace();
    if (Consume(']')) return;
    while (true) {
      value.array.push_back(ParseValue(depth + 1));
      SkipWhitespace();
      if (Consume(']')) return;
      Expect(',');
    }
  }

  // JSON number grammar: -?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)?
  std::string ParseNumber() {
    const size_t begin = pos_;
    Consume('-');
    if (Consume('0')) {
      // A leading zero stands alone.
    } else if (!ConsumeDigits()) {
      Fail("malformed number");
    }
    if (Consume('.') && !ConsumeDigits()) Fail("malformed number");
    if (Consume('e') || Consume('E')) {
      if (!Consume('+')) Consume('-');
      if (!ConsumeDigits()) Fail("malformed number");
    }
    return text_.substr(begin, pos_ - begin);
  }

  bool ConsumeDigits() {
    const size_t begin = pos_;
    while (pos_ < text_.size() && text_[pos_] >= '0' && text_[pos_] <= '9') ++pos_;
    return pos_ > begin;
  }

  unsigned ParseHex4() {
    if (text_.size() - pos_ < 4) Fail("truncated \\u escape");
    unsigned code = 0;
    for (int i = 0; i < 4; ++i) {
      const char h = text_[pos_++];
      code <<= 4;
      if (h >= '0' && h <= '9') {
        code |= static_cast<unsigned>(h - '0');
      } else if (h >= 'a' && h <= 'f') {
        code |= static_cast<unsigned>(h - 'a' + 10);
      } else if (h >= 'A' && h <= 'F') {
        code |= static_cast<unsigned>(h - 'A' + 10);
      } else {
        Fail("bad hex digit in \\u escape");
      }
    }
    return code;
  }

  static void AppendUtf8(std::string& out, unsigned code) {
    if (code < 0x80) {
      out += static_cast<char>(code);
    } else if (code < 0x800) {
      out += static_cast<char>(0xC0 | (code >> 6));
      out += static_cast<char>(0x80 | (code & 0x3F));
    } else if (code < 0x10000) {
      out += static_cast<char>(0xE0 | (code >> 12));
      out += static_cast<char>(0x80 | ((code >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (code & 0x3F));
    } else {
      out += static_cast<char>(0xF0 | (code >> 18));
      out += static_cast<char>(0x80 | ((code >> 12) & 0x3F));
      out += static_cast<char>(0x80 | ((code >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (code & 0x3F));
    }
  }

  std::string ParseString() {
    Expect('"');
    std::string out;
    while (true) {
      if (pos_ >= text_.size()) Fail("unterminated string");
      const char c = text_[pos_++];
      if (c == '"') return out;
      if (static_cast<unsigned char>(c) < 0x20) Fail("control character in string");
      if (c != '\\') {
        out += c;
        continue;
      }
      if (pos_ >= text_.size()) Fail("unterminated escape");
      const char e = text_[pos_++];
      switch (e) {
        case '"':
          out += '"';
          break;
        case '\\':
          out += '\\';
          break;
        case '/':
          out += '/';
          break;
        case 'b':
          out += '\b';
          break;
        case 'f':
          out += '\f';
          break;
        case 'n':
          out += '\n';
          break;
        case 'r':
          out += '\r';
          break;
        case 't':
          out += '\t';
          break;
        case 'u': {
          unsigned code = ParseHex4();
          if (code >= 0xD800 && code <= 0xDBFF) {
            // A high surrogate must be followed by an escaped low surrogate.
            if (!Consume('\\') || !Consume('u')) Fail("unpaired surrogate");
            const unsigned low = ParseHex4();
            if (low < 0xDC00 || low > 0xDFFF) Fail("unpaired surrogate");
            code = 0x10000 + ((code - 0xD800) << 10) + (low - 0xDC00);
          } else if (code >= 0xDC00 && code <= 0xDFFF) {
            Fail("unpaired surrogate");
          }
          AppendUtf8(out, code);
          break;
        }
        default:
          Fail(std::string("bad escape '\\") + e + "'");
      }
    }
  }

  const std::string& text_;
  size_t pos_ = 0;
};

}  // namespace

const Value* Value::Find(const std::string& key) const {
  if (type != Type::kObject) return nullptr;
  for (const auto& [name, value] : object) {
    if (name == key) return &value;
  }
  return nullptr;
}

Value Parse(const std::string& text) { return Parser(text).ParseDocument(); }

uint64_t AsUint64(const Value& value) {
  if (value.type != Value::Type::kNumber) {
    throw std::runtime_error("json: expected a number");
  }
  const std::string& t = value.text;
  // Digits only: no sign, fraction or exponent (a safetensors size is an
  // integer; "1e3" or "1.0" is rejected rather than guessed at).
  if (t.empty() || t.size() > 20) throw std::runtime_error("json: not a uint64: " + t);
  uint64_t result = 0;
  for (const char c : t) {
    if (c < '0' || c > '9') throw std::runtime_error("json: not a uint64: " + t);
    const uint64_t digit = static_cast<uint64_t>(c - '0');
    if (result > (UINT64_MAX - digit) / 10) throw std::runtime_error("json: uint64 overflow: " + t);
    result = result * 10 + digit;
  }
  return result;
}

std::string Quote(const std::string& s) {
  static const char kHex[] = "0123456789abcdef";
  std::string out = "\"";
  for (const char c : s) {
    const unsigned char u = static_cast<unsigned char>(c);
    if (c == '"') {
      out += "\\\"";
    } else if (c == '\\') {
      out += "\\\\";
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c == '\r') {
      out += "\\r";
    } else if (u < 0x20) {
      out += "\\u00";
      out += kHex[u >> 4];
      out += kHex[u & 0xF];
    } else {
      out += c;
    }
  }
  out += '"';
  return out;
}

}  // namespace dispmvs::model::json
