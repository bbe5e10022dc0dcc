#include "pipeline/checked_load.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <sstream>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "io/pickle.hpp"
#include "io/zip.hpp"

namespace th::pipeline {
namespace fs = std::filesystem;

torch::ScalarType storage_type(const std::string& cls, const std::string& source) {
  static const std::map<std::string, torch::ScalarType> types = {
      {"torch.FloatStorage", torch::kFloat},  {"torch.DoubleStorage", torch::kDouble},
      {"torch.HalfStorage", torch::kHalf},    {"torch.BFloat16Storage", torch::kBFloat16},
      {"torch.LongStorage", torch::kLong},    {"torch.IntStorage", torch::kInt},
      {"torch.ShortStorage", torch::kShort},  {"torch.CharStorage", torch::kChar},
      {"torch.ByteStorage", torch::kByte},    {"torch.BoolStorage", torch::kBool},
      {"torch.UntypedStorage", torch::kByte},  // a bare storage (2.x); numel counts bytes
  };
  const auto it = types.find(cls);
  if (it == types.end()) fail(source, ": unsupported storage type '", cls, "'");
  return it->second;
}

namespace {

// The storages a pickle of a checkpoint names (persistent ids ('storage', type, key, location,
// numel)) must be records of exactly numel elements: LibTorch's own reader trusts numel and
// would read past a shorter record.
void check_storage_records(const io::ZipSource& source, const std::vector<io::ZipEntry>& entries,
                           const std::string& name, const std::string& pickle) {
  const io::ZipEntry* pkl = nullptr;
  std::map<std::string, const io::ZipEntry*> records;
  const std::string prefix = pickle.substr(0, pickle.size() - std::string("data.pkl").size());
  for (const auto& e : entries) {
    if (e.name == pickle) pkl = &e;
    if (e.name.compare(0, prefix.size() + 5, prefix + "data/") == 0)
      records[e.name.substr(prefix.size() + 5)] = &e;
  }
  if (pkl == nullptr) return;
  const std::string where = name + "/" + pickle;
  io::PickleExtensions ext;
  ext.class_prefixes = {"__torch__."};  // TorchScript's module classes
  ext.ignore_dict_state = true;
  ext.persistent_load = [&](const io::Value& pid) -> io::Value {
    const auto& t = pid.as_list();
    if (t.size() < 5 || t[0].as_str() != "storage")
      fail(where, ": unexpected persistent id ", pid.type_name());
    const auto dtype = storage_type(t[1].as_object().cls, where);
    const std::string key = t[2].as_str();
    const int64_t numel = t[4].as_int();
    const auto it = records.find(key);
    if (it == records.end())
      fail(where, ": names storage record 'data/", key, "', which the archive lacks");
    const auto item = static_cast<int64_t>(c10::elementSize(dtype));
    if (numel < 0 || it->second->size % static_cast<uint64_t>(item) != 0 ||
        it->second->size / static_cast<uint64_t>(item) != static_cast<uint64_t>(numel))
      fail(name, "/", it->second->name, ": a storage record of ", it->second->size, " bytes where ",
           numel, " elements of ", item, " bytes are claimed (a truncated or corrupt record)");
    return io::Value();
  };
  auto none = [](const io::Value::List&) { return io::Value(); };
  for (const char* f :
       {"torch._utils._rebuild_tensor", "torch._utils._rebuild_tensor_v2",
        "torch._utils._rebuild_parameter", "torch._utils._rebuild_parameter_with_state",
        "torch.torch_version.TorchVersion", "collections.Counter"})
    ext.globals[f] = none;
  // TorchScript's typed containers: the container itself.
  auto first = [](const io::Value::List& a) { return a.empty() ? io::Value() : a[0]; };
  for (const char* f :
       {"torch.jit._pickle.restore_type_tag", "torch.jit._pickle.build_intlist",
        "torch.jit._pickle.build_doublelist", "torch.jit._pickle.build_boollist",
        "torch.jit._pickle.build_tensorlist", "torch.jit._pickle.build_tensor_from_id"})
    ext.globals[f] = first;
  for (const char* s : {"FloatStorage", "DoubleStorage", "HalfStorage", "BFloat16Storage",
                        "LongStorage", "IntStorage", "ShortStorage", "CharStorage", "ByteStorage",
                        "BoolStorage", "UntypedStorage"})
    ext.globals[std::string("torch.") + s] = nullptr;
  io::parse_pickle(io::read_member(source, *pkl, name), where, ext);
}

}  // namespace

void check_checkpoint_archive(const fs::path& path) {
  if (!fs::exists(path)) fail("checkpoint '", path.string(), "' does not exist");
  refuse_special_file(path, "checkpoint");
  // Storage records are stored (torch.save and LibTorch align them for memory mapping); LibTorch
  // deflates only its small code/ entries. A compressed member is bounded before it is inflated.
  constexpr uint64_t kMaxInflated = uint64_t{64} << 20;
  const io::FileSource source(path);
  const auto entries = io::list_zip(source, path.string());
  for (const auto& entry : entries) {
    if (entry.method == 0) continue;
    const std::string where = path.string() + "/" + entry.name;
    if (entry.name.find("/data/") != std::string::npos)
      fail(where, ": a compressed storage record (zip method ", entry.method,
           "); torch.save and LibTorch store them uncompressed, so this file was repacked "
           "(save it again with torch.save)");
    if (entry.size > kMaxInflated || entry.size > entry.compressed_size * 1032 + 1024)
      fail(where, ": a compressed member claiming ", entry.size, " bytes from ",
           entry.compressed_size, " (a checkpoint's compressed members are small code files)");
  }
  // <archive>/data.pkl and <archive>/version, as torch.save and LibTorch write them (LibTorch's
  // reader is not opened on anything else: it leaks when its constructor throws).
  bool pickle = false, version = false;
  for (const auto& entry : entries) {
    const auto slash = entry.name.find('/');
    if (slash == std::string::npos || entry.name.find('/', slash + 1) != std::string::npos)
      continue;
    const std::string leaf = entry.name.substr(slash + 1);
    version = version || leaf == "version";
    if (leaf != "data.pkl") continue;
    pickle = true;
    check_storage_records(source, entries, path.string(), entry.name);
  }
  if (!pickle || !version)
    fail(path.string(), ": not a PyTorch checkpoint (no <archive>/",
         pickle ? "version" : "data.pkl", " record)");
}

namespace {

std::string index_text(int64_t flat, c10::IntArrayRef sizes) {
  std::vector<int64_t> index(sizes.size());
  for (size_t d = sizes.size(); d-- > 0;) {
    index[d] = flat % sizes[d];
    flat /= sizes[d];
  }
  std::ostringstream out;
  out << c10::IntArrayRef(index);
  return out.str();
}

}  // namespace

void check_view(c10::IntArrayRef sizes, c10::IntArrayRef strides, int64_t offset,
                int64_t storage_elements, const std::string& what) {
  auto bad_view = [&](const std::string& why) {
    fail(what, " (shape ", sizes, ", strides ", strides, ", offset ", offset, ") ", why,
         ": a truncated or corrupt record");
  };
  if (sizes.size() != strides.size())
    bad_view("has " + std::to_string(strides.size()) + " stride(s) for " +
             std::to_string(sizes.size()) + " size(s)");
  if (offset < 0) bad_view("starts before its storage");
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  int64_t numel = 1, last = offset;
  for (size_t d = 0; d < sizes.size(); ++d) {
    if (sizes[d] < 0 || strides[d] < 0) bad_view("has a negative size or stride");
    if (sizes[d] == 0) return;  // no element is read
    if (numel > kMax / sizes[d]) bad_view("has more elements than can be counted");
    numel *= sizes[d];
    if (strides[d] > 0 && (sizes[d] - 1) > (kMax - last) / strides[d])
      bad_view("reaches past any storage");
    last += (sizes[d] - 1) * strides[d];
  }
  if (last >= storage_elements)
    bad_view("needs " + std::to_string(last + 1) + " elements of its storage, which holds " +
             std::to_string(storage_elements));
  if (numel > storage_elements)
    bad_view("views " + std::to_string(numel) + " elements of a storage of " +
             std::to_string(storage_elements) + " (an overlapping, expanded view is not a weight)");
}

void check_finite(const torch::Tensor& t, const std::string& what) {
  if (!(t.is_floating_point() || t.is_complex()) || t.numel() == 0) return;
  const auto bad = torch::logical_not(torch::isfinite(t)).flatten();
  if (!bad.any().item<bool>()) return;
  const int64_t first = bad.nonzero()[0].item<int64_t>();
  const double value = torch::real(t.flatten()[first]).to(torch::kDouble).item<double>();
  fail(what, " holds ", std::isnan(value) ? "NaN" : "an infinite value", " at index ",
       index_text(first, t.sizes()), " (", bad.sum().item<int64_t>(), " of ", t.numel(),
       " values are not finite)");
}

void check_loaded_tensor(const torch::Tensor& t, const std::string& source,
                         const std::string& name) {
  const std::string what = source + ": tensor '" + name + "'";
  if (!t.defined()) fail(what, " is undefined");
  const auto item = static_cast<int64_t>(t.element_size());
  check_view(t.sizes(), t.strides(), t.storage_offset(),
             static_cast<int64_t>(t.storage().nbytes()) / item, what);
  check_finite(t, what);
}

ParameterKeys config_keys_for(const std::string& name) {
  // Our dotted module paths (METHOD 8 names the reference's), most specific first.
  static const std::vector<std::pair<std::string, ParameterKeys>> table = {
      {"human.ViT.blocks.", {"model.transhe.depth", "model.transhe.dim / model.transhe.mlp_dim"}},
      {"human.ViT.", {"model.transhe.enabled", "model.transhe.dim"}},
      {"human.fc_0.",
       {"model.representation",
        "model.transhe.dim / model.dparf.coordinate / model.dparf.pe_freqs"}},
      {"human.embed.", {"model.representation", "model.spc.channels / model.transhe.dim"}},
      {"human.conv.", {"model.representation", "model.spc.channels"}},
      {"human.", {"model.fdi.human", "model.representation"}},
      {"fdi.alpha_res_0.", {"model.fdi.appearance", "model.fdi.raw_rgb"}},
      {"fdi.key0.", {"model.fdi.appearance", ""}},
      {"fdi.value0.", {"model.fdi.appearance", ""}},
      {"fdi.key1.", {"model.fdi.human", ""}},
      {"fdi.value1.", {"model.fdi.human", ""}},
      {"heads.rgb_res_", {"model.fdi.appearance", "model.fdi.raw_rgb"}},
      {"encoder.upsample_color.", {"model.fdi.raw_rgb", ""}},
      {"encoder.reduction_layer.", {"", "model.fdi.raw_rgb"}},
  };
  for (const auto& [prefix, keys] : table)
    if (name.rfind(prefix, 0) == 0) return keys;
  return {};
}

namespace {

std::string decided_by(const std::string& key) {
  return key.empty() ? std::string() : " (decided by " + key + ")";
}

using Copies = std::vector<std::pair<torch::Tensor, torch::Tensor>>;

void collect(torch::nn::Module& module, torch::serialize::InputArchive& archive,
             const std::string& source, const std::string& prefix, Copies& copies) {
  std::set<std::string> known;
  auto visit = [&](const std::string& key, const torch::Tensor& dst, bool buffer) {
    known.insert(key);
    const std::string name = prefix + key;
    torch::Tensor read;
    bool found = false;
    try {
      found = archive.try_read(key, read, buffer);
    } catch (const c10::Error& e) {
      fail(source, ": tensor '", name, "' cannot be read: ", e.what_without_backtrace());
    }
    if (!found)
      fail(source, ": has no tensor '", name, "', which this model has",
           decided_by(config_keys_for(name).presence));
    check_loaded_tensor(read, source, name);
    if (read.sizes() != dst.sizes())
      fail(source, ": tensor '", name, "' has shape ", read.sizes(), ", this model's is ",
           dst.sizes(), decided_by(config_keys_for(name).shape));
    copies.emplace_back(dst, read);
  };
  for (auto& p : module.named_parameters(/*recurse=*/false)) visit(p.key(), p.value(), false);
  for (auto& b : module.named_buffers(/*recurse=*/false)) visit(b.key(), b.value(), true);
  for (const auto& child : module.named_children()) {
    if (!child.value()->is_serializable()) continue;
    known.insert(child.key());
    const std::string name = prefix + child.key();
    torch::serialize::InputArchive sub;
    bool found = false;
    try {
      found = archive.try_read(child.key(), sub);
    } catch (const c10::Error& e) {
      fail(source, ": module '", name, "' cannot be read: ", e.what_without_backtrace());
    }
    if (!found)
      fail(source, ": has no module '", name, "', which this model has",
           decided_by(config_keys_for(name + ".").presence));
    collect(*child.value(), sub, source, name + ".", copies);
  }
  // What the file holds beyond the model: a checkpoint of another configuration.
  for (const auto& key : archive.keys()) {
    if (known.count(key)) continue;
    c10::IValue value;
    if (!archive.try_read(key, value) ||
        !(value.isTensor() || value.isModule() || value.isObject()))
      continue;
    const std::string name = prefix + key;
    fail(source, ": holds ", value.isTensor() ? "tensor" : "module", " '", name,
         "', which this model does not have",
         decided_by(config_keys_for(value.isTensor() ? name : name + ".").presence));
  }
}

}  // namespace

void load_module_checked(torch::nn::Module& module, torch::serialize::InputArchive& archive,
                         const std::string& source) {
  Copies copies;
  collect(module, archive, source, "", copies);
  torch::NoGradGuard no_grad;
  for (auto& [dst, src] : copies) dst.copy_(src);
}

namespace {

constexpr const char* kConfigKey = "model_config";

// Model keys that do not change the function a checkpoint computes. The k-means file's path is
// where the stored token labels came from on the machine that trained (the labels themselves are
// in the checkpoint).
bool compared(const std::string& key) {
  return key != "model.encoder.pretrained" && key != "model.grouping.cache_dir" &&
         key != "model.grouping.kmeans_file";
}

}  // namespace

void write_model_config(torch::serialize::OutputArchive& archive, const ModelConfig& config) {
  archive.write(kConfigKey, c10::IValue(YAML::Dump(config::to_tree(config))));
}

std::vector<std::string> model_config_differences(torch::serialize::InputArchive& archive,
                                                  const fs::path& checkpoint,
                                                  const ModelConfig& config) {
  YAML::Node trained;
  std::string origin;
  c10::IValue stored;
  if (archive.try_read(kConfigKey, stored) && stored.isString()) {
    try {
      trained = YAML::Load(stored.toStringRef());
    } catch (const YAML::Exception& e) {
      fail(checkpoint.string(), ": its stored model config is not YAML (", e.what(), ")");
    }
    origin = "checkpoint";
  } else if (checkpoint.parent_path().filename() == "checkpoints") {
    const fs::path run_config = checkpoint.parent_path().parent_path() / "config.yaml";
    if (!fs::exists(run_config)) return {};
    try {
      trained = YAML::LoadFile(run_config.string())["model"];
    } catch (const YAML::Exception& e) {
      fail(run_config.string(), ": cannot be read (", e.what(), ")");
    }
    origin = "run config";
  }
  if (!trained || !trained.IsMap()) return {};
  const auto before = config::leaves(trained, "model");
  const auto now = config::leaves(config::to_tree(config), "model");
  std::vector<std::string> out;
  for (const auto& [key, value] : now) {
    if (!compared(key)) continue;
    const auto it = before.find(key);
    if (it == before.end()) continue;  // a key added since the checkpoint was written
    if (it->second != value)
      out.push_back(key + ": " + origin + " " + it->second + ", config " + value);
  }
  return out;
}

}  // namespace th::pipeline
