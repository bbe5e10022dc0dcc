// transhuman-report: the HTML report page of the demo (scores, training curve, orbit, mesh
// viewer, gallery) or of an ablation run (rows side by side). transhuman-eval writes its own.
#include "report/report.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <fstream>
#include <iostream>

#include "app/app.hpp"
#include "core/error.hpp"

namespace fs = std::filesystem;

namespace {

// The first comment line of configs/ablations/<row>.yaml: what the row changes.
std::string describe(const fs::path& config) {
  std::ifstream in(config);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind('#', 0) == 0) {
      const size_t start = line.find_first_not_of("# ");
      return start == std::string::npos ? "" : line.substr(start);
    }
  return "";
}

// Refuses an input folder that a running command is writing (it holds the folder's lock,
// th::app::lock_run_dir): its results are not finished. Only looks: the lock file is neither made
// nor written, and the lock is not kept.
void refuse_folder_in_use(const fs::path& dir, const std::string& what) {
  const fs::path file = dir / ".lock";
  const int fd = ::open(file.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return;  // no lock file: no writer
  const bool busy = ::flock(fd, LOCK_SH | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  ::close(fd);
  if (!busy) return;
  std::string holder;
  std::getline(std::ifstream(file), holder);
  th::fail(what, " '", dir.string(), "' is in use by ", holder.empty() ? "another process" : holder,
           ": its results are not finished (wait for it to end)");
}

// Takes the lock of the report's folder (made when missing) for as long as the report runs: a
// running evaluation or another report in the same folder refuses it, naming its holder.
void lock_report_folder(const fs::path& out) {
  fs::create_directories(out);
  th::app::lock_run_dir(out, "transhuman-report");
}

double train_seconds(const fs::path& train_done) {
  std::ifstream in(train_done);
  double s = NAN;
  if (in >> s) return s;
  return NAN;
}

}  // namespace

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-report", [&]() -> int {
    CLI::App cli{"Write an HTML report page (index.html) that opens from its folder in a browser."};
    cli.require_subcommand(1);
    std::string out, title;

    auto* page = cli.add_subcommand("page", "an evaluation or demo page");
    th::report::PageSources sources;
    std::vector<std::string> evals, links;
    std::string metrics, orbit, mesh;
    page->add_option("--out", out, "the report folder (index.html and what it shows)")->required();
    page->add_option("--eval", evals, "transhuman-eval output folder(s)")
        ->required()
        ->check(CLI::ExistingDirectory);
    page->add_option("--metrics", metrics, "a training run's metrics.jsonl (training curve)");
    page->add_option("--orbit", orbit, "transhuman-render's output folder (frames/, video.mp4)")
        ->check(CLI::ExistingDirectory);
    page->add_option("--mesh", mesh, "a .ply from transhuman-mesh")->check(CLI::ExistingFile);
    page->add_option("--link", links,
                     "LABEL=HREF: a link in the page's header (relative to the page)");
    page->add_option("--title", title, "the page's title");

    auto* ablations =
        cli.add_subcommand("ablations", "an ablation run: rows side by side, paired against full");
    std::string root = "runs/ablations", setting = "identity", configs = "configs/ablations";
    std::vector<std::string> rows;
    ablations->add_option("--root", root,
                          "scripts/run_ablations.sh's output folder (ROOT/<row>/eval_<setting>)");
    ablations->add_option("--setting", setting, "the evaluation setting");
    ablations->add_option("--configs", configs,
                          "the folder of the rows' configs (for their descriptions)");
    ablations->add_option("--title", title, "the page's title");
    ablations->add_option("rows", rows, "row names")->required();
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;

    fs::path written;
    if (*page) {
      if (!title.empty()) sources.title = title;
      sources.evals.assign(evals.begin(), evals.end());
      sources.metrics = metrics;
      sources.orbit = orbit;
      sources.mesh = mesh;
      for (const auto& link : links) {
        const size_t eq = link.find('=');
        if (eq == std::string::npos) th::fail("--link '", link, "': expected LABEL=HREF");
        sources.links.emplace_back(link.substr(0, eq), link.substr(eq + 1));
      }
      for (const auto& e : sources.evals) refuse_folder_in_use(e, "evaluation folder (--eval)");
      lock_report_folder(out);
      written = th::report::write_page(sources, out);
    } else {
      std::vector<th::report::AblationRow> list;
      for (const auto& row : rows) {
        const fs::path run = fs::path(root) / row;
        list.push_back({row, describe(fs::path(configs) / (row + ".yaml")),
                        run / ("eval_" + setting), train_seconds(run / "train_done")});
      }
      for (const auto& row : list) refuse_folder_in_use(row.eval, "evaluation folder");
      lock_report_folder(root);
      written = th::report::write_ablation_page(
          list, title.empty() ? "TransHuman ablations (" + setting + ")" : title, root);
    }
    std::cout << "report: " << written.string() << "\n";
    return 0;
  });
}
