#pragma once
// A small, strict JSON reader and writer, enough for safetensors headers:
// objects, arrays, strings (with escapes, \uXXXX incl. surrogate pairs),
// integers and numbers, true/false/null. Object keys keep file order; duplicate
// keys are rejected. Nesting depth is bounded so hostile input cannot blow the
// stack.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace dispmvs::model::json {

struct Value {
  enum class Type { kNull, kBool, kNumber, kString, kArray, kObject };
  Type type = Type::kNull;
  bool boolean = false;
  // kNumber: the literal text as written, so integers never pass through a
  // double (sizes above 2^53 stay exact).
  std::string text;  // kString: the decoded string; kNumber: the literal
  std::vector<Value> array;
  std::vector<std::pair<std::string, Value>> object;

  // Lookup in an object; nullptr when absent (or not an object).
  const Value* Find(const std::string& key) const;
};

// Throws std::runtime_error("json: ... at byte N") on malformed input or
// trailing garbage (trailing whitespace is allowed).
Value Parse(const std::string& text);

// Parses a kNumber that is a non-negative integer fitting in uint64_t;
// throws std::runtime_error otherwise.
uint64_t AsUint64(const Value& value);

// A JSON string literal (with quotes) for `s`; control characters and
// quotes/backslashes are escaped, other bytes are copied (UTF-8 passes through).
std::string Quote(const std::string& s);

}  // namespace dispmvs::model::json
