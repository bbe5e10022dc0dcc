// The run folder of every executable: what --force may remove, which folders render and mesh
// continue in, and the lock that keeps a second writer out.
#include <sys/wait.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <fstream>
#include <functional>
#include <string>
#include <thread>

#include "app/app.hpp"
#include "core/error.hpp"
#include "support/test_env.hpp"

namespace fs = std::filesystem;
using th::app::claim_run_dir;

namespace {

void touch(const fs::path& file) {
  fs::create_directories(file.parent_path());
  std::ofstream(file) << "x";
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const th::Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("clearing with --force never removes a folder holding an input or lying inside one",
          "[app][run-folder]") {
  const fs::path root = th::test::scratch_dir("run_folder_inputs");
  touch(root / "run" / "checkpoints" / "latest.pt");
  touch(root / "run" / "metrics.jsonl");
  touch(root / "data" / "p" / "annots.npy");
  const YAML::Node none;
  const th::app::Inputs inputs{
      {"the checkpoint (--checkpoint)", (root / "run" / "checkpoints" / "latest.pt").string()},
      {"the data root (data.root)", (root / "data").string()}};
  CHECK_THAT(error_of([&] { claim_run_dir(root / "run", none, true, false, inputs); }),
             Catch::Contains("--force would delete the checkpoint (--checkpoint) '" +
                             (root / "run" / "checkpoints" / "latest.pt").string() + "'"));
  CHECK_THAT(error_of([&] { claim_run_dir(root / "data" / "p", none, true, false, inputs); }),
             Catch::Contains("--force would delete part of the data root (data.root)"));
  // Through a link or a "..", the same folder.
  fs::create_directory_symlink(root / "run", root / "link");
  CHECK_THAT(error_of([&] { claim_run_dir(root / "link", none, true, false, inputs); }),
             Catch::Contains("--force would delete the checkpoint"));
  CHECK_THAT(
      error_of([&] { claim_run_dir(root / "data" / ".." / "run", none, true, false, inputs); }),
      Catch::Contains("--force would delete the checkpoint"));
  CHECK(fs::exists(root / "run" / "checkpoints" / "latest.pt"));
  CHECK(fs::exists(root / "data" / "p" / "annots.npy"));
  // A folder holding none of them is cleared, its lock file kept.
  touch(root / "other" / "results.md");
  touch(root / "other" / ".lock");
  CHECK_NOTHROW(claim_run_dir(root / "other", none, true, false, inputs));
  CHECK_FALSE(fs::exists(root / "other" / "results.md"));
  CHECK(fs::exists(root / "other" / ".lock"));
}

TEST_CASE("render and mesh continue in a folder of their own outputs and refuse another command's",
          "[app][run-folder]") {
  const fs::path root = th::test::scratch_dir("run_folder_own");
  const YAML::Node none;
  const std::vector<std::string> own{"config.yaml", "log.txt", "frames", "*.ply"};
  touch(root / "mine" / "config.yaml");
  touch(root / "mine" / "frames" / "frame_0000.png");
  touch(root / "mine" / "p_frame0000.ply");
  touch(root / "mine" / ".lock");
  CHECK_NOTHROW(claim_run_dir(root / "mine", none, false, false, {}, own));
  CHECK(fs::exists(root / "mine" / "frames" / "frame_0000.png"));  // continued, not cleared
  touch(root / "run" / "config.yaml");
  touch(root / "run" / "checkpoints" / "latest.pt");
  CHECK_THAT(
      error_of([&] { claim_run_dir(root / "run", none, false, false, {}, own); }),
      Catch::Contains("already holds 1 entry (checkpoints) that this command does not write"));
  CHECK(fs::exists(root / "run" / "config.yaml"));
  // Train and eval (no own outputs): any entry but the lock file.
  CHECK_THAT(error_of([&] { claim_run_dir(root / "mine", none, false, false); }),
             Catch::Contains("already holds 3 entries"));
}

TEST_CASE("a run folder has one writer: a second is refused naming the first, until it ends",
          "[app][lock]") {
  const fs::path dir = th::test::scratch_dir("run_folder_lock");
  int ready[2], go[2];
  REQUIRE(::pipe(ready) == 0);
  REQUIRE(::pipe(go) == 0);
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {  // the first writer: takes the lock, says so, waits for the word to end
    int code = 0;
    try {
      th::app::lock_run_dir(dir, "first-writer");
    } catch (...) {
      code = 1;
    }
    char c = 'r';
    (void)!::write(ready[1], &c, 1);
    (void)!::read(go[0], &c, 1);
    ::_exit(code);
  }
  char c = 0;
  REQUIRE(::read(ready[0], &c, 1) == 1);
  CHECK_THAT(error_of([&] { th::app::lock_run_dir(dir, "second"); }),
             Catch::Contains("run folder '" + dir.string() + "' is in use by first-writer (pid " +
                             std::to_string(child) + " on ") &&
                 Catch::Contains("one writer at a time"));
  (void)!::write(go[1], &c, 1);
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
  // The lock went with its process: the next writer takes it.
  const int fd = th::app::lock_run_dir(dir, "second");
  CHECK(fd >= 0);
  std::ifstream in(dir / ".lock");
  std::string holder;
  std::getline(in, holder);
  CHECK(holder == "second (pid " + std::to_string(::getpid()) + " on " + [] {
    char host[256] = {};
    ::gethostname(host, sizeof host - 1);
    return std::string(host);
  }() + ")");
  ::close(fd);
}
