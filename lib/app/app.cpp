#include "app/app.hpp"

#include <spdlog/spdlog.h>

#include <iostream>

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
      ->check(CLI::NonNegativeNumber);
  cli.add_flag("--dry-run", o.dry_run, "build everything the config names, print a summary, exit");
  cli.add_flag("-v,--verbose", o.verbose, "debug logging");
  cli.add_option("overrides", o.overrides, "config overrides, e.g. train.lr=1e-4 model.dparf.nk=1");
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
  if (o.threads >= 0) overrides.push_back("threads=" + std::to_string(o.threads));

  RunContext ctx;
  ctx.resolved = config::load_tree(o.config, overrides);
  ctx.config = config::from_tree<Config>(ctx.resolved);
  ctx.resolved = config::to_tree(ctx.config);  // every field, defaults included

  const std::string out = !o.out.empty() ? o.out : default_out;
  if (!out.empty()) {
    ctx.run_dir = out;
    std::error_code ec;
    fs::create_directories(ctx.run_dir, ec);
    if (ec) fail("cannot create run directory '", out, "': ", ec.message());
    logging::add_file_sink(ctx.run_dir / "log.txt");
    config::write_yaml(ctx.run_dir / "config.yaml", ctx.resolved);
  }

  spdlog::info("{} | config {} | {}", app_name, o.config,
               ctx.run_dir.empty() ? "no run directory" : "run directory " + ctx.run_dir.string());
  runtime::log_blas();
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
    return 2;
  } catch (const c10::Error& e) {
    std::cerr << app_name << ": internal error: " << e.what_without_backtrace() << std::endl;
    return 3;
  } catch (const std::exception& e) {
    std::cerr << app_name << ": internal error: " << e.what() << std::endl;
    return 3;
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
