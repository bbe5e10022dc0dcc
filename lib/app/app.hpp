#pragma once
// What every executable shares: common command-line options, config loading with overrides,
// the run directory (resolved config + log), BLAS/device/thread set-up, and one-line errors.

#include <torch/types.h>

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/config.hpp"

namespace th::app {

struct CommonOptions {
  std::string config = "configs/default.yaml";
  std::vector<std::string> overrides;  // key.sub=value
  std::string out;                     // run directory
  std::string device;                  // overrides config `device` when set
  std::string precision;               // overrides config `precision` when set
  int threads = -1;                    // overrides config `threads` when >= 0
  bool dry_run = false;
  bool verbose = false;
  bool quiet = false;  // errors only on the console (data-parallel ranks other than 0)
  // --out must be empty or new unless --force (replace its contents) or, for training, --resume
  // (continue the run there; the model section of its config.yaml must be unchanged).
  bool guard_out = false;
  bool force = false;
  // The command trains (transhuman-train): model.encoder.pretrained is read. Every other command
  // takes the encoder's weights from its checkpoint and does not read that file.
  bool training = false;
  // The command scores views (transhuman-eval): eval.lpips_weights is read.
  bool scoring = false;
  bool resume = false;
  // What the command writes into --out, as entry names ("frames", "*.ply"): render and mesh
  // continue in a folder holding only these; anything else makes --out another command's
  // folder (refused unless --force). Empty: --out must be empty.
  std::vector<std::string> own_outputs;
  // Inputs named on the command line (what, path): --force never clears a folder that holds one
  // or lies inside one. start_run adds the config's own (config file, data root, split file,
  // body model, weights files).
  std::vector<std::pair<std::string, std::string>> inputs;
  // Run by start_run once the config is loaded, before the run folder is written: checks that
  // need the data (the first training sample), so that a failing run leaves nothing behind.
  std::function<void(const Config&)> preflight;
};

// Registers --config, --out, --device, --threads, --dry-run, --verbose and the positional
// key=value overrides on `cli`.
void add_common_options(CLI::App& cli, CommonOptions& options);

// Registers --precision (the commands that run the network: train, eval, render, mesh).
void add_precision_option(CLI::App& cli, CommonOptions& options);

// A CLI11 check: the value is a finite number (not nan or inf).
CLI::Validator finite_number();
// A CLI11 check: the value is a number >= `min` (the message quotes the bound, not a range).
CLI::Validator at_least(double min);
CLI::Validator above(double bound);  // a number > bound
// A number in [min, max] (CLI11's own Range words its message differently across versions).
CLI::Validator in_range(double min, double max);

// Registers --force on `cli` (with `help`, or the default text) and turns on the --out guard.
void add_force_option(CLI::App& cli, CommonOptions& options, const std::string& help = "");

// A named input of a command (what it is, where).
using Inputs = std::vector<std::pair<std::string, std::string>>;

// The --out guard of start_run: a folder that holds entries other than `own_outputs` (and the
// lock file) is refused unless `force` (its contents are removed, after checking that none of
// `inputs` lies inside it and that it lies inside none of them) or `resume` (the model keys
// of its config.yaml must equal `resolved`'s; those that differ are named). Throws th::Error.
// With `check_only`, every check runs and nothing is removed.
void claim_run_dir(const std::filesystem::path& dir, const YAML::Node& resolved, bool force,
                   bool resume, const Inputs& inputs = {},
                   const std::vector<std::string>& own_outputs = {}, bool check_only = false);

// The inputs a config names (config file, data root, split file, body model, weights files).
Inputs config_inputs(const Config& config, const std::string& config_file);

// Takes the run folder's lock (flock on `dir`/.lock, held until the process exits): a second
// writer is refused, naming the holder's command, pid and host. Returns the lock file's
// descriptor.
int lock_run_dir(const std::filesystem::path& dir, const std::string& app_name);

// What the commands that use a trained model share (eval, render, mesh): the checkpoint and
// the split setting whose people and reference views they use.
struct ModelOptions {
  std::string checkpoint;              // ours (.pt) or the reference's (.pth)
  std::string setting;                 // overrides eval.setting when set
  std::string reference_views;         // "a,b,c": overrides data.reference_views when given
  bool reference_views_given = false;  // given, even as '' (refused)
};

// Registers --checkpoint, --setting and --reference-views on `cli`.
void add_model_options(CLI::App& cli, ModelOptions& model);
// After parsing: turns --setting and --reference-views into overrides and fails unless a checkpoint
// is named (a dry run needs none).
void apply_model_options(const ModelOptions& model, CommonOptions& options);

struct RunContext {
  Config config;
  YAML::Node resolved;            // the config as a tree, every field included
  std::filesystem::path run_dir;  // empty when the command writes nothing (dry run, no --out)
  torch::Device device = torch::kCPU;
};

// Loads the config (file + overrides + --device/--threads), sets up logging, threads and the
// device, and, when `out` is set (or `default_out` is non-empty), creates the run directory
// with config.yaml and log.txt. Logs the BLAS in use.
RunContext start_run(const CommonOptions& options, const std::string& app_name,
                     const std::string& default_out = "");

// Runs `body` and turns every failure into one line on stderr and a non-zero exit code:
// 2 for user errors (th::Error, bad command line), 3 for internal errors.
int guarded_main(const std::string& app_name, const std::function<int()>& body);

// Parses the command line. Returns the exit code when the program should stop now: 0 after
// --help, 2 after a parse error (unknown flag, missing or invalid value), reported as one line
// "<app>: error: ..." on stderr; nothing when the program goes on. Integers are decimal ("010"
// is ten) and numbers are never hexadecimal, in every option of `cli` and its subcommands.
// Every executable (apps/, bench/) parses its command line here.
std::optional<int> parse_command_line(CLI::App& cli, int argc, char** argv);

// "Model  6,922,244" style thousands separators.
std::string with_commas(int64_t n);

}  // namespace th::app
