#include "model/safetensors.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>

#include "model/json.h"

namespace dispmvs::model {
namespace {

// Headers of real weights files are a few KB; this bound keeps a corrupted
// length field from making us read (and parse) gigabytes.
constexpr uint64_t kMaxHeaderBytes = uint64_t{100} << 20;
// Matches the reference implementation's limit on tensor rank.
constexpr size_t kMaxRank = 64;

struct DTypeInfo {
  const char* name;
  torch::ScalarType type;
  uint64_t item_size;
};

// The safetensors dtypes that LibTorch 1.13 can hold. (U16/U32/U64 and the
// F8 types exist in the format but have no LibTorch 1.13 counterpart.)
const DTypeInfo kDTypes[] = {
    {"F64", torch::kFloat64, 8},   {"F32", torch::kFloat32, 4}, {"F16", torch::kFloat16, 2},
    {"BF16", torch::kBFloat16, 2}, {"I64", torch::kInt64, 8},   {"I32", torch::kInt32, 4},
    {"I16", torch::kInt16, 2},     {"I8", torch::kInt8, 1},     {"U8", torch::kUInt8, 1},
    {"BOOL", torch::kBool, 1},
};

const DTypeInfo* FindDType(const std::string& name) {
  for (const DTypeInfo& info : kDTypes) {
    if (name == info.name) return &info;
  }
  return nullptr;
}

const DTypeInfo* FindDType(torch::ScalarType type) {
  for (const DTypeInfo& info : kDTypes) {
    if (type == info.type) return &info;
  }
  return nullptr;
}

std::string ShapeString(c10::IntArrayRef shape) {
  std::ostringstream out;
  out << '[';
  for (size_t i = 0; i < shape.size(); ++i) out << (i ? "," : "") << shape[i];
  out << ']';
  return out.str();
}

std::string DTypeName(torch::ScalarType type) {
  const DTypeInfo* info = FindDType(type);
  return info ? info->name : std::string(c10::toString(type));
}

// The format is little-endian; we copy tensor memory as is.
void RequireLittleEndianHost() {
  const uint16_t probe = 1;
  unsigned char first = 0;
  std::memcpy(&first, &probe, 1);
  if (first != 1) throw std::runtime_error("safetensors: big-endian hosts are not supported");
}

[[noreturn]] void FileError(const std::string& path, const std::string& what) {
  throw std::runtime_error("safetensors " + path + ": " + what);
}

// a * b, or false on uint64 overflow.
bool MultiplyChecked(uint64_t a, uint64_t b, uint64_t* out) {
  if (a != 0 && b > UINT64_MAX / a) return false;
  *out = a * b;
  return true;
}

struct TensorEntry {
  std::string name;
  const DTypeInfo* dtype = nullptr;
  std::vector<int64_t> shape;
  uint64_t begin = 0;  // byte offsets into the data section
  uint64_t end = 0;
};

struct Header {
  std::map<std::string, std::string> metadata;
  std::vector<TensorEntry> entries;  // sorted by data offset
  uint64_t data_start = 0;           // file offset of the data section
};

TensorEntry ParseEntry(const std::string& path, const std::string& name, const json::Value& value,
                       uint64_t data_size) {
  const auto fail = [&](const std::string& what) -> void {
    FileError(path, "tensor '" + name + "': " + what);
  };
  if (value.type != json::Value::Type::kObject) fail("entry is not an object");
  for (const auto& [key, unused] : value.object) {
    if (key != "dtype" && key != "shape" && key != "data_offsets")
      fail("unknown key '" + key + "'");
  }
  const json::Value* dtype = value.Find("dtype");
  const json::Value* shape = value.Find("shape");
  const json::Value* offsets = value.Find("data_offsets");
  if (!dtype || !shape || !offsets) fail("needs dtype, shape and data_offsets");

  TensorEntry entry;
  entry.name = name;
  if (dtype->type != json::Value::Type::kString) fail("dtype is not a string");
  entry.dtype = FindDType(dtype->text);
  if (entry.dtype == nullptr) fail("unsupported dtype '" + dtype->text + "'");

  if (shape->type != json::Value::Type::kArray) fail("shape is not an array");
  if (shape->array.size() > kMaxRank) fail("rank above " + std::to_string(kMaxRank));
  uint64_t numel = 1;
  for (const json::Value& dim : shape->array) {
    uint64_t size = 0;
    try {
      size = json::AsUint64(dim);
    } catch (const std::runtime_error& e) {
      fail(std::string("bad shape: ") + e.what());
    }
    if (size > static_cast<uint64_t>(INT64_MAX) || !MultiplyChecked(numel, size, &numel)) {
      fail("shape too large");
    }
    entry.shape.push_back(static_cast<int64_t>(size));
  }
  uint64_t bytes = 0;
  if (!MultiplyChecked(numel, entry.dtype->item_size, &bytes)) fail("shape too large");

  if (offsets->type != json::Value::Type::kArray || offsets->array.size() != 2) {
    fail("data_offsets must be [begin, end]");
  }
  try {
    entry.begin = json::AsUint64(offsets->array[0]);
    entry.end = json::AsUint64(offsets->array[1]);
  } catch (const std::runtime_error& e) {
    fail(std::string("bad data_offsets: ") + e.what());
  }
  if (entry.begin > entry.end || entry.end > data_size) {
    fail("data_offsets [" + std::to_string(entry.begin) + ", " + std::to_string(entry.end) +
         "] outside the data section of " + std::to_string(data_size) + " bytes");
  }
  if (entry.end - entry.begin != bytes) {
    fail("data_offsets span " + std::to_string(entry.end - entry.begin) + " bytes but " +
         ShapeString(entry.shape) + " " + entry.dtype->name + " needs " + std::to_string(bytes));
  }
  return entry;
}

// Reads and validates everything but the tensor data. `in` is left open.
Header ReadHeader(const std::string& path, std::ifstream& in) {
  RequireLittleEndianHost();
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    FileError(path, std::filesystem::exists(path, error)
                        ? "not a regular file"
                        : "cannot open for reading (no such file)");
  }
  in.open(path, std::ios::binary);
  if (!in) FileError(path, "cannot open for reading");
  in.seekg(0, std::ios::end);
  const std::streamoff file_size_signed = in.tellg();
  if (file_size_signed < 0) FileError(path, "cannot determine the file size");
  const uint64_t file_size = static_cast<uint64_t>(file_size_signed);
  in.seekg(0, std::ios::beg);
  if (file_size < 8) FileError(path, "file too short for the header length");

  unsigned char length_bytes[8];
  in.read(reinterpret_cast<char*>(length_bytes), 8);
  if (!in) FileError(path, "cannot read the header length");
  uint64_t header_size = 0;
  for (int i = 7; i >= 0; --i) header_size = (header_size << 8) | length_bytes[i];
  if (header_size > file_size - 8) {
    FileError(path, "header length " + std::to_string(header_size) + " exceeds the file size " +
                        std::to_string(file_size));
  }
  if (header_size > kMaxHeaderBytes) {
    FileError(path, "header length " + std::to_string(header_size) + " above the limit");
  }
  std::string text(static_cast<size_t>(header_size), '\0');
  in.read(text.data(), static_cast<std::streamsize>(header_size));
  if (!in) FileError(path, "cannot read the header");

  json::Value root;
  try {
    root = json::Parse(text);
  } catch (const std::runtime_error& e) {
    FileError(path, std::string("malformed header: ") + e.what());
  }
  if (root.type != json::Value::Type::kObject) FileError(path, "header is not a JSON object");

  Header header;
  header.data_start = 8 + header_size;
  const uint64_t data_size = file_size - header.data_start;
  for (const auto& [name, value] : root.object) {
    if (name == "__metadata__") {
      if (value.type != json::Value::Type::kObject)
        FileError(path, "__metadata__ is not an object");
      for (const auto& [key, item] : value.object) {
        if (item.type != json::Value::Type::kString) {
          FileError(path, "__metadata__ value of '" + key + "' is not a string");
        }
        header.metadata[key] = item.text;
      }
      continue;
    }
    header.entries.push_back(ParseEntry(path, name, value, data_size));
  }

  // The data section must be tiled exactly: no overlaps, no holes, nothing
  // after the last tensor (as the reference implementation demands).
  std::stable_sort(header.entries.begin(), header.entries.end(),
                   [](const TensorEntry& a, const TensorEntry& b) {
                     return a.begin != b.begin ? a.begin < b.begin : a.end < b.end;
                   });
  uint64_t expected_begin = 0;
  for (const TensorEntry& entry : header.entries) {
    if (entry.begin != expected_begin) {
      FileError(path, "tensor '" + entry.name + "' starts at byte " + std::to_string(entry.begin) +
                          " of the data section, expected " + std::to_string(expected_begin) +
                          " (overlap or hole)");
    }
    expected_begin = entry.end;
  }
  if (expected_begin != data_size) {
    FileError(path, "data section has " + std::to_string(data_size) +
                        " bytes but the tensors cover " + std::to_string(expected_begin));
  }
  return header;
}

std::string BuildHeader(const NamedTensors& cpu_tensors,
                        const std::map<std::string, std::string>& metadata) {
  std::string out = "{";
  bool first = true;
  if (!metadata.empty()) {
    out += "\"__metadata__\":{";
    for (const auto& [key, value] : metadata) {
      if (!first) out += ',';
      first = false;
      out += json::Quote(key) + ':' + json::Quote(value);
    }
    out += '}';
    first = false;
  }
  uint64_t offset = 0;
  for (const auto& [name, tensor] : cpu_tensors) {
    const uint64_t bytes = static_cast<uint64_t>(tensor.numel()) * tensor.element_size();
    out += first ? "" : ",";
    first = false;
    out += json::Quote(name) + ":{\"dtype\":\"" + FindDType(tensor.scalar_type())->name +
           "\",\"shape\":[";
    for (int64_t d = 0; d < tensor.dim(); ++d) {
      if (d) out += ",";
      out += std::to_string(tensor.size(d));
    }
    out += "],\"data_offsets\":[" + std::to_string(offset) + ',' + std::to_string(offset + bytes) +
           "]}";
    offset += bytes;
  }
  out += '}';
  // Pad so the data section starts 8-byte aligned.
  while (out.size() % 8 != 0) out += ' ';
  return out;
}

std::string TemporaryPathBeside(const std::string& path) {
  std::random_device random;
  std::ostringstream tag;
  tag << std::hex << random() << random();
  return path + ".tmp-" + tag.str();
}

}  // namespace

void SaveSafetensors(const std::string& path, const NamedTensors& tensors,
                     const std::map<std::string, std::string>& metadata) {
  RequireLittleEndianHost();
  std::set<std::string> names;
  NamedTensors cpu_tensors;
  cpu_tensors.reserve(tensors.size());
  for (const auto& [name, tensor] : tensors) {
    if (name.empty() || name == "__metadata__") {
      throw std::invalid_argument("SaveSafetensors " + path + ": invalid tensor name '" + name +
                                  "'");
    }
    if (!names.insert(name).second) {
      throw std::invalid_argument("SaveSafetensors " + path + ": duplicate tensor name '" + name +
                                  "'");
    }
    if (!tensor.defined()) {
      throw std::invalid_argument("SaveSafetensors " + path + ": tensor '" + name +
                                  "' is undefined");
    }
    if (FindDType(tensor.scalar_type()) == nullptr) {
      throw std::invalid_argument("SaveSafetensors " + path + ": tensor '" + name +
                                  "' has unsupported dtype " + c10::toString(tensor.scalar_type()));
    }
    cpu_tensors.emplace_back(name, tensor.detach().to(torch::kCPU).contiguous());
  }
  const std::string header = BuildHeader(cpu_tensors, metadata);

  const std::string temporary = TemporaryPathBeside(path);
  try {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    if (!out) throw std::runtime_error("safetensors " + path + ": cannot open " + temporary);
    unsigned char length_bytes[8];
    uint64_t length = header.size();
    for (unsigned char& byte : length_bytes) {
      byte = static_cast<unsigned char>(length & 0xFF);
      length >>= 8;
    }
    out.write(reinterpret_cast<const char*>(length_bytes), 8);
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    for (const auto& [name, tensor] : cpu_tensors) {
      const auto bytes = static_cast<std::streamsize>(tensor.numel() * tensor.element_size());
      if (bytes > 0) out.write(static_cast<const char*>(tensor.data_ptr()), bytes);
    }
    out.close();
    if (!out) throw std::runtime_error("safetensors " + path + ": write failed");
    std::filesystem::rename(temporary, path);
  } catch (const std::filesystem::filesystem_error& e) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw std::runtime_error("safetensors " + path + ": " + e.what());
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw;
  }
}

SafetensorsFile LoadSafetensors(const std::string& path) {
  std::ifstream in;
  const Header header = ReadHeader(path, in);
  SafetensorsFile file;
  file.metadata = header.metadata;
  in.seekg(static_cast<std::streamoff>(header.data_start), std::ios::beg);
  // Entries tile the data section in order, so the data is one sequential
  // read; every size below was checked against the file size.
  for (const TensorEntry& entry : header.entries) {
    torch::Tensor tensor =
        torch::empty(entry.shape, torch::TensorOptions().dtype(entry.dtype->type));
    const auto bytes = static_cast<std::streamsize>(entry.end - entry.begin);
    if (bytes > 0) {
      in.read(static_cast<char*>(tensor.data_ptr()), bytes);
      if (!in) FileError(path, "cannot read the data of tensor '" + entry.name + "'");
    }
    if (entry.dtype->type == torch::kBool) {
      // Any byte other than 0/1 is not a valid bool for LibTorch.
      const auto* data = static_cast<const unsigned char*>(tensor.data_ptr());
      for (std::streamsize i = 0; i < bytes; ++i) {
        if (data[i] > 1) FileError(path, "tensor '" + entry.name + "' holds a bool other than 0/1");
      }
    }
    file.tensors.emplace_back(entry.name, std::move(tensor));
  }
  return file;
}

namespace {

// Parameters, then buffers, each group sorted by name.
NamedTensors ModuleTensors(const torch::nn::Module& module) {
  NamedTensors parameters;
  // Undefined tensors (an absent optional parameter) have nothing to store.
  for (const auto& item : module.named_parameters(/*recurse=*/true)) {
    if (item.value().defined()) parameters.emplace_back(item.key(), item.value());
  }
  NamedTensors buffers;
  for (const auto& item : module.named_buffers(/*recurse=*/true)) {
    if (item.value().defined()) buffers.emplace_back(item.key(), item.value());
  }
  const auto by_name = [](const auto& a, const auto& b) { return a.first < b.first; };
  std::sort(parameters.begin(), parameters.end(), by_name);
  std::sort(buffers.begin(), buffers.end(), by_name);
  parameters.insert(parameters.end(), buffers.begin(), buffers.end());
  return parameters;
}

}  // namespace

void SaveModuleWeights(const torch::nn::Module& module, const ModelConfig& config,
                       const std::string& path) {
  config.Check();
  SaveSafetensors(path, ModuleTensors(module), config.ToMetadata());
}

std::map<std::string, std::string> ReadSafetensorsMetadata(const std::string& path) {
  std::ifstream in;
  return ReadHeader(path, in).metadata;
}

ModelConfig ReadModelConfig(const std::string& path) {
  const std::map<std::string, std::string> metadata = ReadSafetensorsMetadata(path);
  try {
    return ModelConfig::FromMetadata(metadata);
  } catch (const std::invalid_argument& e) {
    FileError(path, e.what());
  }
}

void LoadModuleWeights(torch::nn::Module& module, const std::string& path) {
  SafetensorsFile file = LoadSafetensors(path);
  std::map<std::string, torch::Tensor> stored;
  for (auto& [name, tensor] : file.tensors) stored[name] = tensor;
  std::map<std::string, torch::Tensor> targets;
  for (const auto& [name, tensor] : ModuleTensors(module)) targets[name] = tensor;

  // Check everything before copying anything, so a bad file leaves the
  // module untouched. Both maps are sorted: walk their union in name order.
  const auto fail = [&](const std::string& what) {
    throw std::runtime_error("LoadModuleWeights " + path + ": " + what);
  };
  std::set<std::string> all_names;
  for (const auto& item : stored) all_names.insert(item.first);
  for (const auto& item : targets) all_names.insert(item.first);
  for (const std::string& name : all_names) {
    const auto target = targets.find(name);
    const auto source = stored.find(name);
    if (source == stored.end()) {
      fail("missing tensor '" + name + "' (module expects " + ShapeString(target->second.sizes()) +
           " " + DTypeName(target->second.scalar_type()) + ")");
    }
    if (target == targets.end()) fail("unexpected tensor '" + name + "' not in the module");
    if (source->second.sizes() != target->second.sizes()) {
      fail("tensor '" + name + "' has shape " + ShapeString(source->second.sizes()) +
           ", module expects " + ShapeString(target->second.sizes()));
    }
    if (source->second.scalar_type() != target->second.scalar_type()) {
      fail("tensor '" + name + "' has dtype " + DTypeName(source->second.scalar_type()) +
           ", module expects " + DTypeName(target->second.scalar_type()));
    }
  }
  torch::NoGradGuard no_grad;
  for (auto& [name, target] : targets) target.copy_(stored.at(name));
}

}  // namespace dispmvs::model
