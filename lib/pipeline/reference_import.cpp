#include "pipeline/reference_import.hpp"

#include <caffe2/serialize/inline_container.h>
#include <torch/torch.h>

#include <algorithm>
#include <sstream>
#include <unordered_map>

#include "core/error.hpp"
#include "io/files.hpp"
#include "io/pickle.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checked_load.hpp"

namespace th::pipeline {

using model::TransHumanImpl;
namespace {

using io::Value;

void flatten(const Value& v, const std::string& prefix, std::map<std::string, torch::Tensor>& out) {
  const auto kind = v.kind();
  if (kind == Value::Kind::Array || kind == Value::Kind::Int || kind == Value::Kind::Float ||
      kind == Value::Kind::Bool) {
    out[prefix] = v.as_tensor();
  } else if (v.kind() == Value::Kind::Dict) {
    for (const auto& [k, item] : v.as_dict())
      if (k.kind() == Value::Kind::Str || k.kind() == Value::Kind::Bytes)
        flatten(item, prefix.empty() ? k.as_str() : prefix + "." + k.as_str(), out);
  }
}

// Reference names of the parts this model has (METHOD 8).
const std::vector<std::pair<std::string, std::string>>& renames() {
  static const std::vector<std::pair<std::string, std::string>> r = {
      {"human.ViT.", "ViT."},
      {"human.fc_0.", "fc_0."},
      {"fdi.key0.", "spatial_key_value_0.key_embed."},
      {"fdi.value0.", "spatial_key_value_0.value_embed."},
      {"fdi.key1.", "spatial_key_value_1.key_embed."},
      {"fdi.value1.", "spatial_key_value_1.value_embed."},
      {"fdi.", ""},
      {"heads.", ""},
      {"encoder.", "encoder."},
  };
  return r;
}

std::map<std::string, torch::Tensor> read_state_dict(const std::filesystem::path& path,
                                                     const std::string& entry) {
  const std::string source = path.string();
  check_checkpoint_archive(path);  // stored records inside the file: no allocation beyond its size
  std::unique_ptr<caffe2::serialize::PyTorchStreamReader> reader;
  try {
    reader = std::make_unique<caffe2::serialize::PyTorchStreamReader>(source);
  } catch (const c10::Error& e) {
    fail(source, ": not a PyTorch zip checkpoint (", e.what_without_backtrace(), ")");
  }
  if (!reader->hasRecord("data.pkl")) fail(source, ": no data.pkl record (not a torch.save file)");
  const auto [pkl, pkl_size] = reader->getRecord("data.pkl");
  std::map<std::string, torch::Tensor> storages;
  // The byte order of the storages: a 'byteorder' record ("little" or "big"; PyTorch 2.x writes
  // one, Debian 12's 1.13 does not); files without one are little-endian.
  bool swap_bytes = false;
  if (reader->hasRecord("byteorder")) {
    const auto [order_data, order_size] = reader->getRecord("byteorder");
    const std::string order(static_cast<const char*>(order_data.get()), order_size);
    if (order != "little" && order != "big")
      fail(source, ": unknown byteorder record '", order, "' (expected little or big)");
    constexpr bool host_big = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
    swap_bytes = (order == "big") != host_big;
  }

  io::PickleExtensions ext;
  ext.ignore_dict_state = true;  // OrderedDict._metadata of state dicts
  ext.persistent_load = [&](const Value& pid) -> Value {
    // ('storage', storage type, key, location, numel)
    const auto& t = pid.as_list();
    if (t.size() < 5 || t[0].as_str() != "storage")
      fail(source, ": unexpected persistent id ", pid.type_name());
    const auto dtype = storage_type(t[1].as_object().cls, source);
    const std::string key = t[2].as_str();
    const int64_t numel = t[4].as_int();
    auto it = storages.find(key);
    if (it == storages.end()) {
      const std::string record = "data/" + key;
      if (!reader->hasRecord(record)) fail(source, ": missing storage record '", record, "'");
      const auto [data, size] = reader->getRecord(record);
      const int64_t itemsize = static_cast<int64_t>(c10::elementSize(dtype));
      if (numel < 0 || size % static_cast<size_t>(itemsize) != 0 ||
          static_cast<int64_t>(size / static_cast<size_t>(itemsize)) != numel)
        fail(source, ": storage '", record, "' has ", size, " bytes, expected ", numel,
             " elements of ", itemsize, " bytes");
      auto tensor = torch::empty({numel}, dtype);
      std::memcpy(tensor.data_ptr(), data.get(), size);
      if (swap_bytes && itemsize > 1) {
        auto* bytes = static_cast<char*>(tensor.data_ptr());
        for (int64_t i = 0; i < numel; ++i)
          std::reverse(bytes + i * itemsize, bytes + (i + 1) * itemsize);
      }
      it = storages.emplace(key, tensor).first;
    }
    return Value::array(it->second);
  };
  auto rebuild = [&](const Value::List& a) -> Value {
    // _rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks[, metadata])
    if (a.size() < 4) fail(source, ": _rebuild_tensor with ", a.size(), " arguments");
    const auto storage = a[0].as_tensor();
    const int64_t offset = a[1].as_int();
    std::vector<int64_t> size, stride;
    for (const auto& s : a[2].as_list()) size.push_back(s.as_int());
    for (const auto& s : a[3].as_list()) stride.push_back(s.as_int());
    if (size.size() != stride.size())
      fail(source, ": a tensor with ", size.size(), " sizes and ", stride.size(), " strides");
    check_view(size, stride, offset, storage.numel(), source + ": a tensor");
    return Value::array(storage.as_strided(size, stride, offset).clone());
  };
  ext.globals["torch._utils._rebuild_tensor_v2"] = rebuild;
  ext.globals["torch._utils._rebuild_tensor"] = rebuild;
  ext.globals["torch._utils._rebuild_parameter"] = [](const Value::List& a) { return a.at(0); };
  // A Parameter with Python attributes (2.x): (data, requires_grad, hooks, state).
  ext.globals["torch._utils._rebuild_parameter_with_state"] = [](const Value::List& a) {
    return a.at(0);
  };
  // torch.__version__ saved in a checkpoint: a str subclass, read as its text.
  ext.globals["torch.torch_version.TorchVersion"] = [](const Value::List& a) {
    return a.empty() ? Value::str("") : a[0];
  };
  ext.globals["collections.Counter"] = [](const Value::List& a) {
    return a.empty() ? Value::dict({}) : a[0];
  };
  for (const char* s : {"FloatStorage", "DoubleStorage", "HalfStorage", "BFloat16Storage",
                        "LongStorage", "IntStorage", "ShortStorage", "CharStorage", "ByteStorage",
                        "BoolStorage", "UntypedStorage"})
    ext.globals[std::string("torch.") + s] = nullptr;

  const Value root = io::parse_pickle(
      std::string_view(static_cast<const char*>(pkl.get()), pkl_size), source + ":data.pkl", ext);
  const Value* net = root.kind() == Value::Kind::Dict ? root.find(entry) : nullptr;
  std::map<std::string, torch::Tensor> out;
  flatten(net ? *net : root, "", out);
  if (out.empty())
    fail(source, ": no tensors found", net ? " under '" + entry + "'" : std::string());
  return out;
}

}  // namespace

std::map<std::string, torch::Tensor> read_torch_state_dict(const std::filesystem::path& path,
                                                           const std::string& entry) {
  // LibTorch's zip reader throws c10::Error for a corrupt record (a damaged local header, data
  // past the end): the file's error like any other, not a bug.
  try {
    return read_state_dict(path, entry);
  } catch (const c10::Error& e) {
    fail(path.string(), ": corrupt PyTorch checkpoint (", e.what_without_backtrace(), ")");
  }
}

std::string reference_name(const std::string& name) {
  for (const auto& [ours, theirs] : renames())
    if (name.rfind(ours, 0) == 0) return theirs + name.substr(ours.size());
  return name;
}

ImportReport import_reference_state(TransHumanImpl& model,
                                    const std::map<std::string, torch::Tensor>& state,
                                    const std::string& source) {
  if (model.config().representation != Representation::transhuman)
    fail(source, ": reference checkpoints hold the TransHuman representation, not '",
         config::name_of(model.config().representation), "'");
  // Check everything first, then copy.
  std::vector<std::pair<torch::Tensor, torch::Tensor>> copies;
  ImportReport report;
  std::set<std::string> used;
  auto visit = [&](const std::string& name, torch::Tensor& dst) {
    const std::string ref = reference_name(name);
    const auto it = state.find(ref);
    if (it == state.end()) {
      if (ref.find("num_batches_tracked") != std::string::npos) return;  // optional buffer
      fail(source, ": missing key '", ref, "' (for ", name, ")");
    }
    auto src = it->second;
    check_finite(src, source + ": tensor '" + ref + "'");
    if (src.dim() == 3 && src.size(2) == 1 && dst.dim() == 2) src = src.squeeze(2);  // Conv1d k=1
    if (src.is_floating_point() != dst.is_floating_point() || src.scalar_type() == torch::kBool)
      fail(source, ": key '", ref, "' holds ", c10::toString(src.scalar_type()),
           " values, the model expects ", c10::toString(dst.scalar_type()),
           " (not a TransHuman reference checkpoint?)");
    if (src.sizes() != dst.sizes())
      fail(source, ": key '", ref, "' has shape ", it->second.sizes(), ", the model expects ",
           dst.sizes(),
           config_keys_for(name).shape.empty()
               ? ""
               : " (decided by " + config_keys_for(name).shape + ")");
    copies.emplace_back(dst, src);
    used.insert(ref);
    report.loaded.push_back(ref);
  };
  for (auto& p : model.named_parameters()) visit(p.key(), p.value());
  for (auto& b : model.named_buffers()) visit(b.key(), b.value());
  // What the reference holds but does not use (METHOD 8) is skipped; any other key means the file
  // is not what it claims to be (another network or version), so nothing is copied.
  static const char* const kUnused[] = {"encoder.model.layer3.", "encoder.model.layer4.",
                                        "encoder.model.fc.",     "ViT.cls_token",
                                        "ViT.mask_token",        "xyzc_net.",
                                        "encoder.PE_color.",     "ViT.PE.",
                                        "PE_relative."};
  for (const auto& [k, v] : state) {
    if (used.count(k)) continue;
    const bool known = std::any_of(std::begin(kUnused), std::end(kUnused),
                                   [&](const char* prefix) { return k.rfind(prefix, 0) == 0; });
    if (!known)
      fail(source, ": key '", k,
           "' is not part of the TransHuman reference network (another model or version?)");
    report.ignored.push_back(k);
  }
  torch::NoGradGuard no_grad;
  for (auto& [dst, src] : copies) dst.copy_(src.to(dst.dtype()));
  return report;
}

ImportReport import_reference_checkpoint(TransHumanImpl& model, const std::filesystem::path& path) {
  return import_reference_state(model, read_torch_state_dict(path, "net"), path.string());
}

}  // namespace th::pipeline
