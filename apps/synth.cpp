// transhuman-synth: writes the synthetic multi-view human dataset (ZJU-MoCap's layout, or
// EasyMocap's with --layout easymocap).
//
//   transhuman-synth --out data/synthetic [--config configs/synth/default.yaml] [key=value ...]
//                    [--layout zju_mocap|easymocap] [--force]

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>

#include "app/app.hpp"
#include "core/config_io.hpp"
#include "core/logging.hpp"
#include "core/progress.hpp"
#include "synth/config.hpp"
#include "synth/generator.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-synth", [&] {
    CLI::App cli{
        "Writes a synthetic multi-view human dataset in ZJU-MoCap's or EasyMocap's layout."};
    std::string out, config_file = "configs/synth/default.yaml", layout;
    std::vector<std::string> overrides;
    bool force = false, verbose = false;
    cli.add_option("-o,--out", out, "dataset folder to write")->required();
    cli.add_option("-c,--config", config_file, "YAML config (may name a parent config)")
        ->capture_default_str();
    cli.add_option("--layout", layout,
                   "zju_mocap (annots.npy) or easymocap (intri.yml, extri.yml, output/smpl); "
                   "default: the config's `layout`")
        ->check(CLI::IsMember({"zju_mocap", "easymocap"}));
    cli.add_flag("--force", force, "replace an existing dataset made with another config");
    cli.add_flag("-v,--verbose", verbose, "debug logging");
    cli.add_option("overrides", overrides, "config overrides, e.g. seed=3 frames=30");
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    th::logging::init_console(verbose);
    if (!layout.empty()) overrides.push_back("layout=" + layout);

    const auto config = th::config::from_tree<th::synth::SynthConfig>(
        th::config::load_tree(config_file, overrides));
    spdlog::info("transhuman-synth | config {} | out {} | seed {}", config_file, out, config.seed);
    const auto s = th::synth::generate(config, out, force);
    const double mb = double(s.bytes) / (1024.0 * 1024.0);
    if (s.skipped) {
      spdlog::info("{} already holds this dataset ({:.1f} MB); nothing to do", out, mb);
      return 0;
    }
    for (const auto& line : s.lines) spdlog::info("  {}", line);
    spdlog::info("wrote {}: {} people x {} frames, {} images, {:.1f} MB in {}", out, s.people,
                 s.frames, s.images, mb, th::Progress::format_duration(s.seconds));
    return 0;
  });
}
