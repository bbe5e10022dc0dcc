#include "app/app.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/logging.hpp"
#include "core/runtime.hpp"

namespace th::app {
namespace fs = std::filesystem;

void add_common_options(CLI::App& cli, CommonOptions& o) {
  cli.add_option("-c,--config", o.config, "YAML config (may name a parent config)")
      ->capture_default_str();
  cli.add_option("-o,--out", o.out, "run directory (resolved config, log, outputs)");
  cli.add_option("--device", o.device, "compute device (overrides the config's 'device')")
      ->check(CLI::IsMember({"auto", "cpu", "cuda"}));
  cli.add_option("--threads", o.threads, "CPU threads for LibTorch (0: one per core)")
      ->check(in_range(0, 4096));
  cli.add_flag("--dry-run", o.dry_run, "build everything the config names, print a summary, exit");
  cli.add_flag("-v,--verbose", o.verbose, "debug logging");
  cli.add_flag_callback(
      "--config-keys",
      [] {
        std::cout << config::describe(config::keys<Config>());
        throw CLI::Success();
      },
      "list every config key: default, accepted values, description; then exit");
  cli.add_option("overrides", o.overrides, "config overrides, e.g. train.lr=1e-4 model.dparf.nk=1");
}

void add_precision_option(CLI::App& cli, CommonOptions& o) {
  cli.add_option(
         "--precision", o.precision,
         "matrix products in fp32, bf16, or auto: bf16 where the CPU has native bf16 dot products "
         "(overrides the config's 'precision')")
      ->check(CLI::IsMember({"fp32", "bf16", "auto"}));
}

namespace {

// A CLI11 check of a number: `ok` decides, `requirement` is what the message says it must be.
CLI::Validator number_check(std::function<bool(double)> ok, const std::string& requirement) {
  return CLI::Validator(
      [ok, requirement](std::string& text) -> std::string {
        try {
          size_t used = 0;
          const double v = std::stod(text, &used);
          if (used == text.size()) return ok(v) ? "" : "must be " + requirement + ", not " + text;
        } catch (const std::exception&) {
        }
        return "'" + text + "' is not a number";
      },
      "NUMBER " + requirement);
}

}  // namespace

CLI::Validator finite_number() {
  return number_check([](double v) { return std::isfinite(v); }, "finite");
}
CLI::Validator at_least(double min) {
  return number_check([min](double v) { return v >= min; }, ">= " + CLI::detail::to_string(min));
}
CLI::Validator in_range(double min, double max) {
  return number_check(
      [min, max](double v) { return v >= min && v <= max; },
      "in [" + CLI::detail::to_string(min) + ", " + CLI::detail::to_string(max) + "]");
}
CLI::Validator above(double bound) {
  return number_check([bound](double v) { return v > bound; },
                      "> " + CLI::detail::to_string(bound));
}

void add_force_option(CLI::App& cli, CommonOptions& o, const std::string& help) {
  cli.add_flag("--force", o.force, help.empty() ? "replace what --out already holds" : help);
  o.guard_out = true;
}

namespace {

// The run folder's lock file: never listed, cleared or counted as the folder's contents.
constexpr const char* kLockFile = ".lock";

// `name` matches `pattern`: equal, or for "*suffix" ending in suffix.
bool matches(const std::string& name, const std::string& pattern) {
  if (pattern.empty() || pattern[0] != '*') return name == pattern;
  const size_t n = pattern.size() - 1;
  return name.size() >= n && name.compare(name.size() - n, n, pattern, 1, n) == 0;
}

// --force is about to clear `dir`: none of the command's inputs may be in it, and it may not be
// part of one (a dataset, a run whose checkpoint is read).
void refuse_clearing_inputs(const fs::path& dir, const Inputs& inputs) {
  for (const auto& [what, path] : inputs) {
    std::error_code ec;
    if (path.empty() || !(fs::exists(path, ec) || fs::is_symlink(path, ec))) continue;
    // As given too: an input reached through a link inside --out would lose the link.
    if (path_within(path, dir) || path_within_as_given(path, dir))
      fail("--force would delete ", what, " '", path,
           "', an input of this command, which lies in --out '", dir.string(),
           "': choose another --out (nothing was removed)");
    if (path_within(dir, path) || path_within_as_given(dir, path))
      fail("--force would delete part of ", what, " '", path,
           "', an input of this command: --out '", dir.string(),
           "' lies inside it (nothing was removed)");
  }
}

}  // namespace

Inputs config_inputs(const Config& c, const std::string& config_file) {
  Inputs in{{"the config", config_file},
            {"the data root (data.root)", c.data.root},
            {"the split file (data.split_file)", c.data.split_file},
            {"the body model (data.smpl_model)", c.data.smpl_model},
            {"the visibility files (data.visibility_root)", c.data.visibility_root},
            {"the encoder weights (model.encoder.pretrained)", c.model.encoder.pretrained},
            {"the k-means file (model.grouping.kmeans_file)",
             c.model.grouping.kmeans_file == kKMeansCompute ? std::string()
                                                            : c.model.grouping.kmeans_file},
            {"the LPIPS weights (train.lpips_weights)", c.train.lpips_weights},
            {"the LPIPS weights (eval.lpips_weights)", c.eval.lpips_weights}};
  return in;
}

void claim_run_dir(const fs::path& dir, const YAML::Node& resolved, bool force, bool resume,
                   const Inputs& inputs, const std::vector<std::string>& own_outputs,
                   bool check_only) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) return;
  if (!fs::is_directory(dir, ec)) fail("--out '", dir.string(), "' is a file, not a folder");
  // The folder's entries, those another command wrote first.
  std::vector<std::string> entries, foreign, links;
  for (const auto& e : fs::directory_iterator(dir)) {
    const auto name = e.path().filename().string();
    if (name == kLockFile) continue;
    bool own = false;
    for (const auto& pattern : own_outputs) own = own || matches(name, pattern);
    (own ? entries : foreign).push_back(name);
    if (e.is_symlink(ec)) links.push_back(name);
  }
  entries.insert(entries.begin(), foreign.begin(), foreign.end());
  if (entries.empty()) return;
  // A folder that is continued (--resume, or a folder of this command's own outputs) is written
  // into as it is: a link there would take the command's writes elsewhere.
  const bool continued = resume || (!own_outputs.empty() && foreign.empty() && !force);
  if (continued && !links.empty())
    fail("--out '", dir.string(), "' holds '", links.front(),
         "', a symbolic link this command did not make: ",
         "its outputs are written into the folder itself (remove the link, or --force to replace "
         "the contents)");
  if (resume) {
    const fs::path previous = dir / "config.yaml";
    if (!fs::exists(previous))
      fail("cannot resume in '", dir.string(), "': it holds no config.yaml");
    YAML::Node stored;
    try {
      stored = YAML::LoadFile(previous.string());
    } catch (const YAML::Exception& e) {
      fail("cannot resume in '", dir.string(), "': its config.yaml cannot be read (", e.what(),
           ")");
    }
    if (!stored.IsMap())
      fail("cannot resume in '", dir.string(), "': its config.yaml is not a map of keys");
    // The model, and what makes the run's samples what they were (seed, data).
    auto before = config::leaves(stored["model"], "model");
    auto now = config::leaves(resolved["model"], "model");
    for (const char* key :
         {"seed", "data.dataset", "data.root", "data.split_file", "data.train_setting"}) {
      const std::string k(key);
      const size_t dot = k.find('.');
      auto leaf = [&](const YAML::Node& root) {
        const YAML::Node n =
            dot == std::string::npos ? root[k] : root[k.substr(0, dot)][k.substr(dot + 1)];
        return n && n.IsScalar() ? n.Scalar() : std::string("absent");
      };
      before[k] = leaf(stored);
      now[k] = leaf(resolved);
    }
    std::string changed;
    for (const auto& [key, value] : now) {
      const auto it = before.find(key);
      if (it == before.end() || it->second != value)
        changed += (changed.empty() ? "" : ", ") + key +
                   " (run: " + (it == before.end() ? "absent" : it->second) + ", now: " + value +
                   ")";
    }
    if (!changed.empty())
      fail("cannot resume the run in '", dir.string(),
           "' with other model, seed or data settings: ", changed,
           " (start a new run in another folder, or --force to replace this one)");
    return;
  }
  // A folder of this command's own outputs is continued (render, mesh).
  if (!own_outputs.empty() && foreign.empty()) return;
  if (!force) {
    const auto& listed = own_outputs.empty() ? entries : foreign;
    std::string some;
    const size_t n = listed.size();
    for (size_t i = 0; i < std::min<size_t>(n, 3); ++i) some += (i ? ", " : "") + listed[i];
    fail("--out '", dir.string(), "' already holds ", n, " entr", n == 1 ? "y" : "ies", " (", some,
         n > 3 ? ", ..." : "", ")", own_outputs.empty() ? "" : " that this command does not write",
         ": choose another folder, --force to replace its contents",
         fs::exists(dir / "checkpoints") && own_outputs.empty()
             ? ", or --resume to continue the run"
         : fs::exists(dir / "rows.jsonl") && own_outputs.empty()
             ? ", or --resume to continue the evaluation"
             : "");
  }
  refuse_clearing_inputs(dir, inputs);
  if (check_only) return;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename() != kLockFile) fs::remove_all(e.path(), ec);
  if (ec) fail("--force: cannot clear '", dir.string(), "': ", ec.message());
}

int lock_run_dir(const fs::path& dir, const std::string& app_name) {
  const fs::path file = dir / kLockFile;
  // Never through a link: a symbolic link in its place is refused by O_NOFOLLOW, a hard link (a
  // file of somewhere else) or anything but a regular file by fstat, before a byte is written.
  const int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK, 0644);
  if (fd < 0 && errno == ELOOP)
    fail("the run folder's lock file '", file.string(),
         "' is a symbolic link: remove it (nothing was written)");
  if (fd < 0)
    fail("cannot open the run folder's lock file '", file.string(), "': ", std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) || st.st_nlink != 1) {
    const bool linked = S_ISREG(st.st_mode) && st.st_nlink > 1;
    ::close(fd);
    fail("the run folder's lock file '", file.string(), "' is ",
         linked ? "a hard link to another file" : "not a regular file",
         ": remove it (nothing was written)");
  }
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    std::string holder;
    std::getline(std::ifstream(file), holder);
    ::close(fd);
    if (err == EWOULDBLOCK)
      fail("run folder '", dir.string(), "' is in use by ",
           holder.empty() ? "another process" : holder,
           ": one writer at a time (wait for it to end, or choose another --out)");
    fail("cannot lock the run folder '", dir.string(), "': ", std::strerror(err));
  }
  char host[256] = {};
  ::gethostname(host, sizeof host - 1);
  const std::string who = app_name + " (pid " + std::to_string(::getpid()) + " on " + host + ")\n";
  if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, who.data(), who.size(), 0) != ssize_t(who.size())) {
    const int err = errno;
    ::close(fd);
    fail("cannot write the run folder's lock file '", file.string(), "': ", std::strerror(err));
  }
  return fd;
}

void add_model_options(CLI::App& cli, ModelOptions& m) {
  cli.add_option("--checkpoint", m.checkpoint, "checkpoint: ours (.pt) or the reference's (.pth)");
  cli.add_option(
      "--setting", m.setting,
      "split setting (pose, identity, one_shot, cross_dataset, fitting); default eval.setting");
  cli.add_option(
         "--reference-views", m.reference_views,
         "reference cameras, comma-separated names or calibration indices (data.reference_views); "
         "default: the split's, or without a split the most evenly spread")
      ->each([&m](const std::string&) { m.reference_views_given = true; });
}

void apply_model_options(const ModelOptions& m, CommonOptions& options) {
  if (!m.setting.empty()) options.overrides.push_back("eval.setting=" + m.setting);
  if (m.reference_views_given && m.reference_views.empty())
    fail("--reference-views '': no camera named (leave the option out for the split's)");
  if (!m.reference_views.empty()) {
    // A YAML list of double-quoted strings: every camera name is read as written.
    std::string list;
    std::stringstream in(m.reference_views);
    for (std::string item; std::getline(in, item, ',');) {
      if (item.empty())
        fail("--reference-views '", m.reference_views, "': an empty camera name (see --help)");
      std::string quoted = "\"";
      for (const char c : item)
        quoted += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
      list += (list.empty() ? "" : ", ") + quoted + "\"";
    }
    options.overrides.push_back("data.reference_views=[" + list + "]");
  }
  options.inputs.push_back({"the checkpoint (--checkpoint)", m.checkpoint});
  if (!options.dry_run && m.checkpoint.empty()) fail("--checkpoint is required");
}

namespace {

// The weight files a config names are made once by a script: a missing one stops the command
// before it starts, with the command that makes it. Empty keys are the documented "off" (checked
// where used).
void require_weight_files(Config& c, bool training, bool scoring) {
  auto require = [](const std::string& key, const std::string& file, const std::string& make,
                    const std::string& off) {
    std::error_code ec;
    if (file.empty() || fs::is_regular_file(file, ec)) return;
    fail(key, ": '", file, "' does not exist: make it once with `", make, " --out ", file,
         "` (docs/USAGE.md, \"Real data\"), or set ", key, ": \"\" (", off, ")");
  };
  const std::string lpips =
      "python3 scripts/export_lpips.py --vgg vgg16-397923af.pth --lin <lpips "
      "repository>/lpips/weights/v0.1/vgg.pth";
  if (training) {
    require("model.encoder.pretrained", c.model.encoder.pretrained,
            "python3 scripts/export_pretrained.py --torchvision",
            "the encoder then starts from random weights");
    if (c.train.lpips_weight > 0)
      require("train.lpips_weights", c.train.lpips_weights, lpips,
              "the perceptual loss term is then off");
  } else if (!c.model.encoder.pretrained.empty()) {
    spdlog::debug("model.encoder.pretrained not read: the checkpoint holds the encoder's weights");
    c.model.encoder.pretrained.clear();
  }
  if (scoring)
    require("eval.lpips_weights", c.eval.lpips_weights, lpips, "LPIPS is then not reported");
}

// The start's log lines.
RunContext finish_start(RunContext& ctx, const CommonOptions& o, const std::string& app_name,
                        bool own_malloc, int threads) {
  spdlog::info("{} | config {} | {}", app_name, o.config,
               ctx.run_dir.empty() ? "no run directory" : "run directory " + ctx.run_dir.string());
  runtime::log_blas();
  if (!own_malloc) spdlog::debug("malloc: glibc defaults (TH_MALLOC=system)");
  spdlog::info("device {} | {} threads", ctx.device.str(), threads);
  return ctx;
}

}  // namespace

RunContext start_run(const CommonOptions& o, const std::string& app_name,
                     const std::string& default_out) {
  logging::init_console(o.verbose);
  if (o.quiet) spdlog::set_level(spdlog::level::err);

  std::vector<std::string> overrides = o.overrides;
  if (!o.device.empty()) overrides.push_back("device=" + o.device);
  if (!o.precision.empty()) overrides.push_back("precision=" + o.precision);
  if (o.threads >= 0) overrides.push_back("threads=" + std::to_string(o.threads));

  RunContext ctx;
  std::vector<fs::path> config_files;  // --config and every parent it names: inputs all
  ctx.resolved = config::load_tree(o.config, overrides, &config_files);
  ctx.config = config::from_tree<Config>(ctx.resolved);
  ctx.resolved = config::to_tree(ctx.config);  // every field, defaults included
  require_weight_files(ctx.config, o.training, o.scoring);
  // What can still refuse the run (TH_MALLOC, threads, the device) is checked before the run
  // folder is touched, so that a corrected rerun is not refused by a folder a failed one wrote.
  const bool own_malloc = runtime::keep_freed_memory();
  const int threads = runtime::set_threads(ctx.config.threads);
  ctx.device = runtime::select_device(ctx.config.device);

  const std::string out = !o.out.empty() ? o.out : default_out;
  if (!out.empty()) {
    auto inputs = config_inputs(ctx.config, o.config);
    for (size_t i = 1; i < config_files.size(); ++i)
      inputs.push_back({"the config's parent (" + config_files[i - 1].filename().string() + ")",
                        config_files[i]});
    inputs.insert(inputs.end(), o.inputs.begin(), o.inputs.end());
    if (o.dry_run) {  // a dry run writes nothing: the folder is checked as the run would check it
      if (o.guard_out)
        claim_run_dir(out, ctx.resolved, o.force, o.resume, inputs, o.own_outputs, true);
      spdlog::info("dry run: --out '{}' is not touched", out);
      return finish_start(ctx, o, app_name, own_malloc, threads);
    }
    ctx.run_dir = out;
    // Checked before anything is written (a refused folder gets no lock file), then again
    // under the lock, which a second writer cannot take, before --force clears the folder.
    auto claim = [&](bool check_only) {
      if (o.guard_out)
        claim_run_dir(ctx.run_dir, ctx.resolved, o.force, o.resume, inputs, o.own_outputs,
                      check_only);
    };
    claim(true);
    if (o.preflight) o.preflight(ctx.config);
    std::error_code ec;
    fs::create_directories(ctx.run_dir, ec);
    if (ec) fail("cannot create run directory '", out, "': ", ec.message());
    static int lock_fd = -1;  // held until the process ends; a later run folder replaces it
    if (lock_fd >= 0) ::close(lock_fd);
    lock_fd = -1;
    lock_fd = lock_run_dir(ctx.run_dir, app_name);
    claim(false);
    logging::add_file_sink(ctx.run_dir / "log.txt");
    config::write_yaml(ctx.run_dir / "config.yaml", ctx.resolved);
  }

  return finish_start(ctx, o, app_name, own_malloc, threads);
}

int guarded_main(const std::string& app_name, const std::function<int()>& body) {
  try {
    return body();
  } catch (const Error& e) {
    std::cerr << app_name << ": error: " << e.what() << std::endl;
    logging::error_to_files(std::string("error: ") + e.what());
    return 2;
  } catch (const fs::filesystem_error& e) {
    // A path the user gave that cannot be used (a symlink loop, no permission, a name too
    // long): a user error, named by path and reason.
    std::string message = "cannot use '" + e.path1().string() + "'";
    if (!e.path2().empty()) message += " or '" + e.path2().string() + "'";
    message += ": " + e.code().message();
    std::cerr << app_name << ": error: " << message << std::endl;
    logging::error_to_files("error: " + message);
    return 2;
  } catch (const c10::Error& e) {
    std::cerr << app_name << ": internal error: " << e.what_without_backtrace() << std::endl;
    logging::error_to_files(std::string("internal error: ") + e.what_without_backtrace());
    return 3;
  } catch (const std::exception& e) {
    std::cerr << app_name << ": internal error: " << e.what() << std::endl;
    logging::error_to_files(std::string("internal error: ") + e.what());
    return 3;
  }
}

namespace {

// CLI11 reads an integer as C does (strtoll with base 0: "010" is eight, "0x10" sixteen). Every
// integer option of `cli` and its subcommands first goes through this transform, which keeps
// decimal integers only and writes them without leading zeros ("010" is ten), and every number
// option refuses hexadecimal ("0x1p3"). The type name CLI11 gives the option (INT, UINT, FLOAT)
// tells them apart.
void decimal_numbers_only(CLI::App& cli) {
  for (CLI::Option* opt : cli.get_options()) {
    const std::string type = opt->get_type_name();
    const std::string base = type.substr(0, type.find(':'));
    if (base == "INT" || base == "UINT") {
      opt->transform(CLI::Validator(
          [](std::string& text) -> std::string {
            if (const auto v = config::decimal_integer(text)) {
              text = std::to_string(*v);
              return "";
            }
            try {
              size_t used = 0;
              std::stod(text, &used);
              if (used == text.size()) return "'" + text + "' is not a decimal integer";
            } catch (const std::exception&) {
            }
            return "'" + text + "' is not a number";
          },
          ""));
    } else if (base == "FLOAT") {
      opt->transform(CLI::Validator(
          [](std::string& text) -> std::string {
            return text.find_first_of("xX") == std::string::npos
                       ? ""
                       : "'" + text + "' is not a decimal number";
          },
          ""));
    }
  }
  for (CLI::App* sub : cli.get_subcommands([](CLI::App*) { return true; }))
    decimal_numbers_only(*sub);
}

}  // namespace

std::optional<int> parse_command_line(CLI::App& cli, int argc, char** argv) {
  decimal_numbers_only(cli);
  try {
    cli.parse(argc, argv);
    return std::nullopt;
  } catch (const CLI::CallForHelp&) {
    std::cout << cli.help();
    return 0;
  } catch (const CLI::CallForAllHelp&) {
    std::cout << cli.help("", CLI::AppFormatMode::All);
    return 0;
  } catch (const CLI::Success&) {  // --config-keys (after the help requests, which derive from it)
    return 0;
  } catch (const CLI::ParseError& e) {
    std::string message = e.what();
    message = message.substr(0, message.find('\n'));
    const std::string app = argc > 0 ? fs::path(argv[0]).filename().string() : cli.get_name();
    std::cerr << app << ": error: " << message << " (see --help)" << std::endl;
    return 2;
  }
}

std::string with_commas(int64_t n) {
  std::string digits = std::to_string(n < 0 ? -n : n);
  std::string out;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return n < 0 ? "-" + out : out;
}

}  // namespace th::app
