#include "model/safetensors.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "model/encoder.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::model {
namespace {

using testing::ReadFileBytes;
using testing::TempDir;
using testing::WriteFileBytes;

// Bit-exact equality (NaN payloads and -0 included).
bool SameBits(const torch::Tensor& a, const torch::Tensor& b) {
  if (a.scalar_type() != b.scalar_type() || a.sizes() != b.sizes()) return false;
  const torch::Tensor ca = a.contiguous(), cb = b.contiguous();
  return std::memcmp(ca.data_ptr(), cb.data_ptr(), ca.numel() * ca.element_size()) == 0;
}

// Runs f, expects std::runtime_error whose message contains every needle.
template <class F>
void ExpectRuntimeError(F f, std::initializer_list<std::string> needles) {
  try {
    f();
    ADD_FAILURE() << "no exception";
  } catch (const std::runtime_error& e) {
    for (const std::string& needle : needles) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos)
          << "'" << needle << "' not in: " << e.what();
    }
  }
}

std::string LittleEndian64(uint64_t v) {
  std::string out(8, '\0');
  for (int i = 0; i < 8; ++i) out[i] = static_cast<char>((v >> (8 * i)) & 0xFF);
  return out;
}

// A file made of a length field, a header and data, as given.
std::string FileBytes(const std::string& header, const std::string& data) {
  return LittleEndian64(header.size()) + header + data;
}

TEST(SafetensorsTest, RoundTripIsBitExactForEveryDtypeAndShape) {
  torch::manual_seed(30);
  TempDir dir;
  const std::string path = dir.Make("t.safetensors").string();
  torch::Tensor special = torch::tensor({0.0f, -0.0f, 1.5f, 0.0f});
  special[3] = std::numeric_limits<float>::quiet_NaN();
  const NamedTensors tensors = {
      {"f64", torch::randn({3, 4}, torch::kFloat64)},
      {"f32", torch::randn({2, 3, 5})},
      {"f32 special", special},
      {"f16", torch::randn({7}).to(torch::kFloat16)},
      {"bf16", torch::randn({2, 2}).to(torch::kBFloat16)},
      {"i64 scalar", torch::tensor(int64_t{-1234567890123})},
      {"i32 empty", torch::zeros({0, 3}, torch::kInt32)},
      {"i16", torch::randint(-30000, 30000, {4}, torch::kInt16)},
      {"i8", torch::randint(-128, 127, {3, 3}, torch::kInt8)},
      {"u8", torch::randint(0, 255, {5}, torch::kUInt8)},
      {"bool", torch::rand({2, 3}) > 0.5},
      {"f32 transposed", torch::randn({3, 4}).t()},
      {"nested.name/with \"quotes\"", torch::ones({1, 1, 1})},
  };
  const std::map<std::string, std::string> metadata = {
      {"plain", "value"}, {"tricky \"key\"", "line\nbreak\ttab \\ back \xc3\xa9"}, {"empty", ""}};
  SaveSafetensors(path, tensors, metadata);

  // The data section starts 8-byte aligned.
  const std::string bytes = ReadFileBytes(path);
  uint64_t header_size = 0;
  for (int i = 7; i >= 0; --i)
    header_size = (header_size << 8) | static_cast<unsigned char>(bytes[i]);
  EXPECT_EQ(header_size % 8, 0u);

  const SafetensorsFile loaded = LoadSafetensors(path);
  EXPECT_EQ(loaded.metadata, metadata);
  ASSERT_EQ(loaded.tensors.size(), tensors.size());
  for (size_t i = 0; i < tensors.size(); ++i) {
    EXPECT_EQ(loaded.tensors[i].first, tensors[i].first);
    EXPECT_TRUE(SameBits(loaded.tensors[i].second, tensors[i].second)) << tensors[i].first;
  }
  EXPECT_EQ(loaded.tensors[5].second.dim(), 0);
  EXPECT_EQ(loaded.tensors[6].second.numel(), 0);
}

TEST(SafetensorsTest, WriterProducesTheDocumentedBytes) {
  TempDir dir;
  const std::string path = dir.Make("one.safetensors").string();
  SaveSafetensors(path, {{"x", torch::tensor({1.0f})}}, {});
  // 54-byte header padded with 2 spaces to 56 = 0x38; 1.0f is 0x3f800000.
  const std::string expected = std::string("\x38\0\0\0\0\0\0\0", 8) +
                               R"({"x":{"dtype":"F32","shape":[1],"data_offsets":[0,4]}}  )" +
                               std::string("\x00\x00\x80\x3f", 4);
  EXPECT_EQ(ReadFileBytes(path), expected);
}

TEST(SafetensorsTest, LoadsAHandWrittenFile) {
  TempDir dir;
  const std::string path = dir.Make("hand.safetensors").string();
  // Tensors listed out of data order, with whitespace and an escaped name; no
  // padding (the format does not require it on read).
  const std::string header =
      "{ \"b\" : {\"shape\": [1, 1], \"dtype\": \"I16\", \"data_offsets\": [8, 10]},\n"
      "  \"__metadata__\": {\"k\": \"v\\u00e9\"},\n"
      "  \"\\u0061\": {\"dtype\": \"F32\", \"shape\": [2], \"data_offsets\": [0, 8]} }";
  // a = [1.0f, -2.5f] = 0x3f800000, 0xc0200000; b = [[-2]] = 0xfffe.
  const std::string data("\x00\x00\x80\x3f\x00\x00\x20\xc0\xfe\xff", 10);
  WriteFileBytes(path, FileBytes(header, data));

  const SafetensorsFile file = LoadSafetensors(path);
  EXPECT_EQ(file.metadata.at("k"), "v\xc3\xa9");
  ASSERT_EQ(file.tensors.size(), 2u);
  EXPECT_EQ(file.tensors[0].first, "a");  // data order
  EXPECT_TRUE(SameBits(file.tensors[0].second, torch::tensor({1.0f, -2.5f})));
  EXPECT_EQ(file.tensors[1].first, "b");
  EXPECT_TRUE(SameBits(file.tensors[1].second, torch::full({1, 1}, -2, torch::kInt16)));
}

TEST(SafetensorsTest, RejectsCorruptFilesNamingThePath) {
  TempDir dir;
  const std::string path = dir.Make("bad.safetensors").string();
  const std::string f32_header = R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]}})";
  const std::string eight(8, '\x01');
  struct Case {
    std::string bytes;
    std::string needle;
  };
  const Case cases[] = {
      {"", "too short"},
      {std::string("\x05\0\0", 3), "too short"},
      {LittleEndian64(1000) + "{}", "exceeds the file size"},
      {LittleEndian64(uint64_t{1} << 63) + "{}", "exceeds the file size"},
      {FileBytes(f32_header, eight.substr(0, 7)), "outside the data section"},
      {FileBytes(f32_header, eight + "x"), "data section has 9 bytes"},
      {FileBytes("{\"a\":", ""), "malformed header"},
      {FileBytes("[1,2]", ""), "not a JSON object"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},"a":{}})", eight),
       "duplicate key"},
      {FileBytes(R"({"a":{"dtype":"U16","shape":[4],"data_offsets":[0,8]}})", eight),
       "unsupported dtype 'U16'"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[3],"data_offsets":[0,8]}})", eight), "needs 12"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[-2],"data_offsets":[0,8]}})", eight), "bad shape"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[2.0],"data_offsets":[0,8]}})", eight),
       "bad shape"},
      {FileBytes(R"({"a":{"dtype":"U8","shape":[4611686018427387904,4],"data_offsets":[0,8]}})",
                 eight),
       "shape too large"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[8,0]}})", eight),
       "outside the data section"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0]}})", eight),
       "data_offsets must be"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[2]}})", eight), "needs dtype, shape"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8],"x":1}})", eight),
       "unknown key 'x'"},
      {FileBytes(R"({"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},)"
                 R"("b":{"dtype":"F32","shape":[1],"data_offsets":[4,8]}})",
                 eight),
       "overlap or hole"},
      {FileBytes(R"({"a":{"dtype":"U8","shape":[4],"data_offsets":[4,8]}})", eight),
       "overlap or hole"},
      {FileBytes(R"({"__metadata__":{"k":1}})", ""), "not a string"},
      {FileBytes(R"({"a":{"dtype":"BOOL","shape":[2],"data_offsets":[0,2]}})", "\x01\x02"),
       "bool other than 0/1"},
  };
  for (const Case& c : cases) {
    WriteFileBytes(path, c.bytes);
    ExpectRuntimeError([&] { LoadSafetensors(path); }, {path, c.needle});
  }
  ExpectRuntimeError([&] { LoadSafetensors(dir.Make("missing.safetensors").string()); },
                     {"cannot open"});
  ExpectRuntimeError([&] { LoadSafetensors(dir.path().string()); }, {"not a regular file"});
}

TEST(SafetensorsTest, TruncatedFilesFail) {
  TempDir dir;
  const std::string good = dir.Make("good.safetensors").string();
  SaveSafetensors(good, {{"a", torch::randn({4, 4})}, {"b", torch::randn({3})}}, {{"k", "v"}});
  const std::string bytes = ReadFileBytes(good);
  const std::string cut = dir.Make("cut.safetensors").string();
  for (size_t size = 0; size < bytes.size(); ++size) {
    WriteFileBytes(cut, bytes.substr(0, size));
    EXPECT_THROW(LoadSafetensors(cut), std::runtime_error) << "size " << size;
  }
}

TEST(SafetensorsTest, SaveRejectsBadInputAndLeavesNoTemporaryFiles) {
  TempDir dir;
  const std::string path = dir.Make("w.safetensors").string();
  EXPECT_THROW(SaveSafetensors(path, {{"a", torch::ones({1})}, {"a", torch::ones({1})}}, {}),
               std::invalid_argument);
  EXPECT_THROW(SaveSafetensors(path, {{"", torch::ones({1})}}, {}), std::invalid_argument);
  EXPECT_THROW(SaveSafetensors(path, {{"c", torch::ones({1}, torch::kComplexFloat)}}, {}),
               std::invalid_argument);
  EXPECT_THROW(SaveSafetensors(dir.Make("no/such/dir").string() + "/x/w.safetensors",
                               {{"a", torch::ones({1})}}, {}),
               std::runtime_error);

  // Overwriting replaces the file as a whole.
  SaveSafetensors(path, {{"a", torch::ones({100})}}, {});
  SaveSafetensors(path, {{"b", torch::zeros({2})}}, {});
  const SafetensorsFile file = LoadSafetensors(path);
  ASSERT_EQ(file.tensors.size(), 1u);
  EXPECT_EQ(file.tensors[0].first, "b");
  int entries = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(dir.path())) {
    if (entry.is_regular_file()) {
      ++entries;
      EXPECT_EQ(entry.path().string(), path);
    }
  }
  EXPECT_EQ(entries, 1);
}

TEST(SafetensorsTest, ModuleRoundTrip) {
  TempDir dir;
  const std::string path = dir.Make("matching.safetensors").string();
  const ModelConfig config = ModelConfig::Small();
  torch::manual_seed(31);
  MatchingEncoder saved(config);
  SaveModuleWeights(*saved, config, path);

  const ModelConfig read = ReadModelConfig(path);
  EXPECT_EQ(read.ToMetadata(), config.ToMetadata());

  torch::manual_seed(32);
  MatchingEncoder loaded(read);
  LoadModuleWeights(*loaded, path);
  const auto a = saved->named_parameters();
  const auto b = loaded->named_parameters();
  ASSERT_EQ(a.size(), b.size());
  for (const auto& item : a) {
    EXPECT_TRUE(SameBits(item.value(), b[item.key()])) << item.key();
  }
  torch::NoGradGuard no_grad;
  const torch::Tensor images = torch::rand({1, 3, 32, 32});
  EXPECT_TRUE(torch::equal(saved->forward(images).fine, loaded->forward(images).fine));

  // Parameters first, each group in name order.
  const SafetensorsFile file = LoadSafetensors(path);
  for (size_t i = 1; i < file.tensors.size(); ++i) {
    EXPECT_LT(file.tensors[i - 1].first, file.tensors[i].first);
  }
}

// The first name, in name order, whose shape differs between two modules.
std::string FirstShapeMismatch(const torch::nn::Module& a, const torch::nn::Module& b) {
  std::map<std::string, torch::Tensor> sa, sb;
  for (const auto& item : a.named_parameters()) sa[item.key()] = item.value();
  for (const auto& item : b.named_parameters()) sb[item.key()] = item.value();
  for (const auto& [name, tensor] : sa) {
    if (sb.count(name) && sb[name].sizes() != tensor.sizes()) return name;
  }
  return "";
}

TEST(SafetensorsTest, LoadModuleWeightsNamesTheFirstMismatch) {
  TempDir dir;
  torch::manual_seed(33);
  const ModelConfig small = ModelConfig::Small();
  MatchingEncoder module(small);
  NamedTensors tensors;
  for (const auto& item : module->named_parameters())
    tensors.emplace_back(item.key(), item.value());
  std::sort(tensors.begin(), tensors.end(),
            [](const auto& x, const auto& y) { return x.first < y.first; });
  const std::string first_name = tensors.front().first;
  const torch::Tensor before = tensors.front().second.clone();

  const std::string path = dir.Make("w.safetensors").string();
  const auto expect_failure = [&](const NamedTensors& file_tensors, const std::string& needle) {
    SaveSafetensors(path, file_tensors, small.ToMetadata());
    ExpectRuntimeError([&] { LoadModuleWeights(*module, path); }, {path, needle});
  };

  NamedTensors missing(tensors.begin() + 1, tensors.end());
  expect_failure(missing, "missing tensor '" + first_name + "'");

  NamedTensors unexpected = tensors;
  unexpected.emplace_back("zzz.extra", torch::ones({2}));
  expect_failure(unexpected, "unexpected tensor 'zzz.extra'");

  NamedTensors wrong_dtype = tensors;
  wrong_dtype.back().second = wrong_dtype.back().second.to(torch::kFloat64);
  expect_failure(wrong_dtype, "tensor '" + wrong_dtype.back().first + "' has dtype F64");

  NamedTensors wrong_shape = tensors;
  wrong_shape[1].second = torch::zeros({3, 1});
  wrong_shape.back().second = torch::zeros({5});  // a later mismatch is not reported
  expect_failure(wrong_shape, "tensor '" + wrong_shape[1].first + "' has shape [3,1]");

  // A whole module of another configuration.
  const std::string paper_path = dir.Make("paper.safetensors").string();
  MatchingEncoder paper(ModelConfig::Paper());
  SaveModuleWeights(*paper, ModelConfig::Paper(), paper_path);
  const std::string mismatch = FirstShapeMismatch(*module, *paper);
  ASSERT_FALSE(mismatch.empty());
  ExpectRuntimeError([&] { LoadModuleWeights(*module, paper_path); },
                     {"tensor '" + mismatch + "' has shape"});

  // Nothing was copied by the failed loads.
  EXPECT_TRUE(SameBits(module->named_parameters()[first_name], before));
}

TEST(SafetensorsTest, ReadModelConfigRequiresTheMetadata) {
  TempDir dir;
  const std::string path = dir.Make("w.safetensors").string();
  SaveSafetensors(path, {{"a", torch::ones({1})}}, {{"name", "x"}});
  ExpectRuntimeError([&] { ReadModelConfig(path); }, {path, "missing key"});
}

}  // namespace
}  // namespace dispmvs::model
