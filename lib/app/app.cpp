#include "app/app.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <iostream>
#include <map>

#include "core/error.hpp"
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
      ->check(CLI::Range(0, 4096).description("0 to 4096"));
  cli.add_flag("--dry-run", o.dry_run, "build everything the config names, print a summary, exit");
  cli.add_flag("-v,--verbose", o.verbose, "debug logging");
  cli.add_option("overrides", o.overrides, "config overrides, e.g. train.lr=1e-4 model.dparf.nk=1");
}

void add_precision_option(CLI::App& cli, CommonOptions& o) {
  cli.add_option("--precision", o.precision,
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
CLI::Validator above(double bound) {
  return number_check([bound](double v) { return v > bound; }, "> " + CLI::detail::to_string(bound));
}

void add_force_option(CLI::App& cli, CommonOptions& o) {
  cli.add_flag("--force", o.force, "replace what --out already holds");
  o.guard_out = true;
}

void claim_run_dir(const fs::path& dir, const YAML::Node& resolved, bool force, bool resume) {
  std::error_code ec;
  if (!fs::exists(dir, ec) || fs::is_empty(dir, ec)) return;
  if (!fs::is_directory(dir, ec)) fail("--out '", dir.string(), "' is a file, not a folder");
  if (resume) {
    const fs::path previous = dir / "config.yaml";
    if (!fs::exists(previous)) fail("cannot resume in '", dir.string(), "': it holds no config.yaml");
    const auto before = config::leaves(YAML::LoadFile(previous.string())["model"], "model");
    const auto now = config::leaves(resolved["model"], "model");
    std::string changed;
    for (const auto& [key, value] : now) {
      const auto it = before.find(key);
      if (it == before.end() || it->second != value)
        changed += (changed.empty() ? "" : ", ") + key + " (run: " + (it == before.end() ? "absent" : it->second) +
                   ", now: " + value + ")";
    }
    if (!changed.empty())
      fail("cannot resume the run in '", dir.string(), "' with other model settings: ", changed,
           " (start a new run in another folder, or --force to replace this one)");
    return;
  }
  if (!force) {
    std::string some;
    int n = 0;
    for (const auto& e : fs::directory_iterator(dir)) {
      if (n++ < 3) some += (some.empty() ? "" : ", ") + e.path().filename().string();
    }
    fail("--out '", dir.string(), "' already holds ", n, " entr", n == 1 ? "y" : "ies", " (", some, n > 3 ? ", ..." : "",
         "): choose another folder, --force to replace its contents",
         fs::exists(dir / "checkpoints") ? ", or --resume to continue the run" : "");
  }
  for (const auto& e : fs::directory_iterator(dir)) fs::remove_all(e.path(), ec);
  if (ec) fail("--force: cannot clear '", dir.string(), "': ", ec.message());
}

void add_model_options(CLI::App& cli, ModelOptions& m) {
  cli.add_option("--checkpoint", m.checkpoint, "checkpoint: ours (.pt) or the reference's (.pth)");
  cli.add_option("--setting", m.setting,
                 "split setting (pose, identity, one_shot, cross_dataset, fitting); default eval.setting");
}

void apply_model_options(const ModelOptions& m, CommonOptions& options) {
  if (!m.setting.empty()) options.overrides.push_back("eval.setting=" + m.setting);
  if (!options.dry_run && m.checkpoint.empty()) fail("--checkpoint is required");
}

RunContext start_run(const CommonOptions& o, const std::string& app_name,
                     const std::string& default_out) {
  logging::init_console(o.verbose);
  if (o.quiet) spdlog::set_level(spdlog::level::err);

  std::vector<std::string> overrides = o.overrides;
  if (!o.device.empty()) overrides.push_back("device=" + o.device);
  if (!o.precision.empty()) overrides.push_back("precision=" + o.precision);
  if (o.threads >= 0) overrides.push_back("threads=" + std::to_string(o.threads));

  RunContext ctx;
  ctx.resolved = config::load_tree(o.config, overrides);
  ctx.config = config::from_tree<Config>(ctx.resolved);
  ctx.resolved = config::to_tree(ctx.config);  // every field, defaults included

  const std::string out = !o.out.empty() ? o.out : default_out;
  if (!out.empty()) {
    ctx.run_dir = out;
    if (o.guard_out) claim_run_dir(ctx.run_dir, ctx.resolved, o.force, o.resume);
    std::error_code ec;
    fs::create_directories(ctx.run_dir, ec);
    if (ec) fail("cannot create run directory '", out, "': ", ec.message());
    logging::add_file_sink(ctx.run_dir / "log.txt");
    config::write_yaml(ctx.run_dir / "config.yaml", ctx.resolved);
  }

  spdlog::info("{} | config {} | {}", app_name, o.config,
               ctx.run_dir.empty() ? "no run directory" : "run directory " + ctx.run_dir.string());
  runtime::log_blas();
  if (!runtime::keep_freed_memory()) spdlog::debug("malloc: glibc defaults (TH_MALLOC=system)");
  const int threads = runtime::set_threads(ctx.config.threads);
  ctx.device = runtime::select_device(ctx.config.device);
  spdlog::info("device {} | {} threads", ctx.device.str(), threads);
  return ctx;
}

int guarded_main(const std::string& app_name, const std::function<int()>& body) {
  try {
    return body();
  } catch (const Error& e) {
    std::cerr << app_name << ": error: " << e.what() << std::endl;
    logging::error_to_files(std::string("error: ") + e.what());
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

std::optional<int> parse_command_line(CLI::App& cli, int argc, char** argv) {
  try {
    cli.parse(argc, argv);
    return std::nullopt;
  } catch (const CLI::CallForHelp&) {
    std::cout << cli.help();
    return 0;
  } catch (const CLI::CallForAllHelp&) {
    std::cout << cli.help("", CLI::AppFormatMode::All);
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
