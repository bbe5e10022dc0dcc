#pragma once
// The HTML report: one page per evaluation, per demo and per ablation run that opens
// from its folder in a browser (file://, no server, no network) and can be zipped and mailed.
//
// The page (index.html) embeds its data (summary.json, per_image.csv, metrics.jsonl and
// config.yaml as text) and is drawn by our own script, report.js (lib/report/assets/). The 3D
// viewer uses three.js's classic scripts from Debian's libjs-three, copied into the folder; the
// mesh travels as base64 in mesh.js because a file:// page may not fetch other files.

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

namespace th::report {

// What an evaluation or demo page shows. Every part but `evals` is optional: an empty path
// leaves that section out.
struct PageSources {
  std::string title = "TransHuman evaluation";
  // transhuman-eval output folders: summary.json, per_image.csv, config.yaml, images/.
  std::vector<std::filesystem::path> evals;
  std::filesystem::path metrics;  // a training run's metrics.jsonl: the training curve
  std::filesystem::path orbit;    // transhuman-render's folder: frames/*.png, video.mp4
  std::filesystem::path mesh;     // a .ply from transhuman-mesh (vertex colours when present)
  std::vector<std::pair<std::string, std::string>> links;  // label, href relative to the page
};

// Writes <out>/index.html, report.js and report.css, and with a mesh three/*.js and mesh.js.
// What the page shows from outside `out` (evaluation panels, orbit frames, video, the .ply) is
// copied in, so the folder is self-contained: an evaluation folder to out/<its name>, the name
// of the folder it resolves to ("e" for "runs/e/" or "runs/e/x/.."), made unique with a suffix
// ("e-2") and never one of the page's own files. Every file is written inside `out` and never
// through a symbolic link found there (a th::Error naming it). Returns the page's path. A
// missing summary.json or per_image.csv is a th::Error naming the file; without libjs-three the
// viewer says so.
std::filesystem::path write_page(const PageSources& sources, const std::filesystem::path& out);

// One row of an ablation table: a configs/ablations/<name>.yaml run and its evaluation.
struct AblationRow {
  std::string name;
  std::string description;     // what the row changes (the config's first comment)
  std::filesystem::path eval;  // its transhuman-eval folder
  double train_seconds = NAN;
};

// Writes <out>/index.html putting the rows side by side: table, a bar chart per metric, and
// paired per-image differences against the row named "full" (when present). Links each row's
// own page (the index.html in its evaluation folder).
std::filesystem::path write_ablation_page(const std::vector<AblationRow>& rows,
                                          const std::string& title,
                                          const std::filesystem::path& out);

// The folder with libjs-three's classic scripts (three.min.js, OrbitControls.js, PLYLoader.js):
// $TH_THREE_JS_DIR when set, else Debian's install paths; empty when none is found.
std::filesystem::path find_three_js();

// The commit the binary was built from ("unknown" outside a git checkout).
std::string build_commit();

// `value` as JSON that is safe inside an HTML <script> element: '<', '>' and '&' in strings are
// written as \u003c, \u003e and \u0026, so no "</script>" or "<!--" ends the element early. Bytes
// that are not UTF-8 become U+FFFD.
std::string script_json(const nlohmann::ordered_json& value);

}  // namespace th::report
