#include <torch/torch.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "core/config_io.hpp"
#include "core/error.hpp"
#include "data/sampler.hpp"
#include "dist/communicator.hpp"
#include "dist/launcher.hpp"
#include "dist/processes.hpp"
#include "model/encoder.hpp"
#include "model/transhuman.hpp"
#include "pipeline/checkpoint.hpp"
#include "support/test_env.hpp"
#include "train/trainer.hpp"

namespace fs = std::filesystem;
using th::test::Process;

namespace {

// The tiny training configuration of tests/train, as command-line overrides.
std::vector<std::string> tiny_overrides(std::vector<std::string> extra = {}) {
  const auto root = th::test::tiny_dataset();
  std::vector<std::string> o{
      "data.root=" + root.string(), "data.split_file=" + (root / "split.yaml").string(),
      "model.grouping.cache_dir=" + (root.parent_path() / "kmeans_cache").string(),
      "train.val_views=0"};
  o.insert(o.end(), extra.begin(), extra.end());
  return o;
}

th::Config tiny_config(std::vector<std::string> extra = {}) {
  return th::config::load<th::Config>("tests/configs/tiny_train.yaml",
                                      tiny_overrides(std::move(extra)));
}

std::vector<std::string> train_command(const fs::path& out,
                                       const std::vector<std::string>& extra_args,
                                       const std::vector<std::string>& overrides) {
  std::vector<std::string> args{th::test::train_executable().string(), "--config",
                                "tests/configs/tiny_train.yaml", "--out", out.string()};
  args.insert(args.end(), extra_args.begin(), extra_args.end());
  args.insert(args.end(), overrides.begin(), overrides.end());
  return args;
}

// Rank `r` of `world` started by hand (as any launcher would).
Process start_rank(int r, int world, int port, const std::vector<std::string>& args,
                   const fs::path& log) {
  return th::test::spawn(
      args,
      {"RANK=" + std::to_string(r), "WORLD_SIZE=" + std::to_string(world),
       "LOCAL_RANK=" + std::to_string(r), "LOCAL_WORLD_SIZE=" + std::to_string(world),
       "MASTER_ADDR=127.0.0.1", "MASTER_PORT=" + std::to_string(port)},
      log);
}

struct State {
  std::map<std::string, torch::Tensor> params, buffers;
  int64_t step = 0;
};

State state_of(const fs::path& checkpoint, const th::Config& c) {
  th::model::TransHuman model(c.model);
  th::pipeline::load_weights(*model, checkpoint);
  State s;
  for (const auto& p : model->named_parameters()) s.params[p.key()] = p.value().clone();
  for (const auto& b : model->named_buffers()) s.buffers[b.key()] = b.value().clone();
  torch::serialize::InputArchive root;
  root.load_from(checkpoint.string());
  torch::Tensor step;
  root.read("step", step);
  s.step = step.item<int64_t>();
  return s;
}

double max_difference(const std::map<std::string, torch::Tensor>& a,
                      const std::map<std::string, torch::Tensor>& b) {
  REQUIRE(a.size() == b.size());
  double d = 0;
  for (const auto& [name, t] : a) d = std::max(d, (t - b.at(name)).abs().max().item<double>());
  return d;
}

size_t count_differing(const std::map<std::string, torch::Tensor>& a,
                       const std::map<std::string, torch::Tensor>& b) {
  size_t n = 0;
  for (const auto& [name, t] : a) n += !torch::equal(t, b.at(name));
  return n;
}

std::string describe(int status) {
  if (WIFEXITED(status)) return "exit " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return "signal " + std::to_string(WTERMSIG(status));
  return "status " + std::to_string(status);
}

// Waits until `file` exists or `process` ends or `seconds` pass; true when the file exists.
bool wait_for_file(const fs::path& file, const Process& process, double seconds) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < deadline) {
    if (fs::exists(file)) return true;
    if (::waitpid(process.pid, nullptr, WNOHANG) == process.pid) return fs::exists(file);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

}  // namespace

TEST_CASE("the sharded sampler gives each rank different samples of the same epoch", "[dist]") {
  const size_t n = 12;
  const th::data::ShardedSampler two(n, 42, 2);
  const auto r0 = two.draw(3, 0, 6, {0}), r1 = two.draw(3, 0, 6, {1});
  // 6 iterations x 2 ranks = the 12 samples of the epoch, each drawn once, by one rank.
  std::multiset<size_t> all(r0.order.begin(), r0.order.end());
  all.insert(r1.order.begin(), r1.order.end());
  CHECK(all.size() == n);
  CHECK(std::set<size_t>(all.begin(), all.end()).size() == n);
  // Both ranks of one process (interleaved per iteration) draw what the two ranks draw apart.
  const auto both = two.draw(3, 0, 6, {0, 1});
  for (size_t it = 0; it < 6; ++it) {
    CHECK(both.order[2 * it] == r0.order[it]);
    CHECK(both.order[2 * it + 1] == r1.order[it]);
    CHECK(both.seeds[2 * it + 1] == r1.seeds[it]);
  }
  CHECK(r0.seeds != r1.seeds);
  // Resuming inside an epoch continues the same sequence.
  const auto tail = two.draw(3, 4, 6, {1});
  CHECK(std::vector<size_t>(r1.order.begin() + 4, r1.order.end()) == tail.order);
  // Another epoch, another order; the same epoch, the same order.
  CHECK(two.draw(4, 0, 6, {0}).order != r0.order);
  CHECK(two.draw(3, 0, 6, {0}).order == r0.order);
  // With one rank the epoch is the permutation itself (cycled when longer than the dataset).
  const th::data::ShardedSampler one(n, 42, 1);
  const auto perm = one.permutation(3);
  const auto single = one.draw(3, 0, int(n) + 2, {0});
  for (size_t i = 0; i < n + 2; ++i) CHECK(single.order[i] == perm[i % n]);
}

TEST_CASE("the workers of --nproc N run this program without it, in the run directory named first",
          "[dist]") {
  const char* argv[] = {"transhuman-train", "--config",  "c.yaml",      "--nproc", "2",
                        "train.epochs=3",   "--nproc=4", "--max-steps", "5"};
  const int argc = int(std::size(argv));
  const auto args = th::dist::worker_args(argc, argv, "runs/train");
  REQUIRE(args.size() == 8);
  // This test binary, as the kernel names it (not the argv[0] given above).
  const std::string self = std::filesystem::read_symlink("/proc/self/exe").string();
  CHECK(th::dist::self_executable() == self);
  CHECK(args[0] == self);
  CHECK(std::vector<std::string>(args.begin() + 1, args.end()) ==
        std::vector<std::string>{"--out", "runs/train", "--config", "c.yaml", "train.epochs=3",
                                 "--max-steps", "5"});
  // With --out given by the user (kept where it is), nothing is added.
  const char* with_out[] = {"transhuman-train", "--out", "mine", "--nproc", "2"};
  CHECK(th::dist::worker_args(3 + 2, with_out, "") ==
        std::vector<std::string>{self, "--out", "mine"});
}

TEST_CASE("the launcher environment is read, and bad values are named", "[dist]") {
  auto set = [](const char* k, const char* v) { v ? ::setenv(k, v, 1) : ::unsetenv(k); };
  const auto keys = {"RANK",        "WORLD_SIZE", "LOCAL_RANK", "LOCAL_WORLD_SIZE",
                     "MASTER_ADDR", "MASTER_PORT"};
  for (const char* k : keys) set(k, nullptr);
  CHECK_FALSE(th::dist::environment_from_env().has_value());
  set("WORLD_SIZE", "4");
  set("RANK", "3");
  set("MASTER_ADDR", "node17");
  set("MASTER_PORT", "29611");
  auto e = th::dist::environment_from_env();
  REQUIRE(e.has_value());
  CHECK(e->world_size == 4);
  CHECK(e->rank == 3);
  CHECK(e->local_rank == 3);
  CHECK(e->master_addr == "node17");
  CHECK(e->master_port == 29611);
  CHECK(e->local_world_size == 1);
  set("LOCAL_WORLD_SIZE", "02");  // decimal, as every integer
  CHECK(th::dist::environment_from_env()->local_world_size == 2);
  set("LOCAL_WORLD_SIZE", "abc");
  CHECK_THROWS_WITH(
      th::dist::environment_from_env(),
      Catch::Contains("environment variable LOCAL_WORLD_SIZE='abc' must be an integer in [1, 4]"));
  set("LOCAL_WORLD_SIZE", "5");
  CHECK_THROWS_WITH(th::dist::environment_from_env(), Catch::Contains("LOCAL_WORLD_SIZE='5'"));
  set("LOCAL_WORLD_SIZE", nullptr);
  set("RANK", " 3");
  CHECK_THROWS_WITH(th::dist::environment_from_env(),
                    Catch::Contains("environment variable RANK=' 3' must be an integer"));
  set("RANK", "4");
  CHECK_THROWS_WITH(th::dist::environment_from_env(),
                    Catch::Contains("environment variable RANK='4' must be an integer in [0, 3]"));
  set("RANK", "x1");
  CHECK_THROWS_WITH(th::dist::environment_from_env(),
                    Catch::Contains("environment variable RANK='x1' must be an integer in [0, 3]"));
  set("RANK", nullptr);
  CHECK_THROWS_WITH(th::dist::environment_from_env(),
                    Catch::Contains("WORLD_SIZE is set (4) but RANK is not"));
  set("RANK", "0");
  set("MASTER_PORT", "70000");
  CHECK_THROWS_WITH(
      th::dist::environment_from_env(),
      Catch::Contains("environment variable MASTER_PORT='70000' must be an integer in [1, 65535]"));
  for (const char* k : keys) set(k, nullptr);
  // NCCL is refused clearly where it cannot work.
  CHECK_THROWS_WITH(
      th::dist::resolve_backend("nccl", torch::kCPU),
      Catch::Contains("train.dist_backend=nccl but this LibTorch was built without NCCL") ||
          Catch::Contains("train.dist_backend=nccl needs device cuda"));
  CHECK(th::dist::resolve_backend("auto", torch::kCPU) == "gloo");
}

TEST_CASE(
    "2 ranks train bit-identical weights, equal to one process accumulating both ranks' samples",
    "[dist][slow]") {
  const int K = 3;
  const fs::path dir = th::test::scratch_dir("dist_two_ranks");
  // Each rank's BatchNorm on its own images: what one process accumulating the two samples one
  // after the other computes (synchronised BatchNorm has its own test below).
  const auto overrides = tiny_overrides({"train.sync_batchnorm=false"});
  // transhuman-train --nproc 2: the launcher starts both ranks.
  const Process launcher =
      th::test::spawn(train_command(dir / "run",
                                    {"--nproc", "2", "--max-steps", std::to_string(K),
                                     "--rank-state", (dir / "ranks").string()},
                                    overrides),
                      {}, dir / "launcher.log");
  const auto status = th::test::wait_for(launcher, 150);
  if (!status) th::test::kill_and_reap(launcher);
  INFO(th::test::read_text(dir / "launcher.log"));
  REQUIRE(status.has_value());
  REQUIRE(describe(*status) == "exit 0");

  const auto c = tiny_config({"train.sync_batchnorm=false"});
  const State r0 = state_of(dir / "ranks" / "rank0.pt", c),
              r1 = state_of(dir / "ranks" / "rank1.pt", c);
  CHECK(r0.step == K);
  CHECK(r1.step == K);
  CHECK(count_differing(r0.params, r1.params) == 0);
  CHECK(count_differing(r0.buffers, r1.buffers) == 0);

  // One process, each step's gradient over the two samples the ranks drew.
  torch::set_num_threads(1);
  th::train::TrainOptions one{dir / "single", false, K};
  one.virtual_ranks = 2;
  one.rank_state_dir = dir / "single_state";
  CHECK(th::train::train(c, torch::kCPU, one).steps == K);
  const State acc = state_of(dir / "single_state" / "rank0.pt", c);
  CHECK(max_difference(r0.params, acc.params) <= 1e-5);

  // Control: training changed the weights well beyond that tolerance, and one process on its
  // own samples ends elsewhere (so the comparison above can fail).
  torch::manual_seed(uint64_t(c.seed));
  th::model::TransHuman fresh(c.model);
  std::map<std::string, torch::Tensor> initial;
  for (const auto& p : fresh->named_parameters()) initial[p.key()] = p.value();
  CHECK(max_difference(r0.params, initial) > 1e-3);
  th::train::TrainOptions alone{dir / "alone", false, K};
  alone.rank_state_dir = dir / "alone_state";
  th::train::train(c, torch::kCPU, alone);
  CHECK(max_difference(r0.params, state_of(dir / "alone_state" / "rank0.pt", c).params) > 1e-4);

  // Rank 0 alone wrote the run: metrics with the world size and the global batch.
  std::ifstream metrics(dir / "run" / "metrics.jsonl");
  std::string line;
  std::getline(metrics, line);
  CHECK_THAT(line, Catch::Contains("\"world_size\": 2") && Catch::Contains("\"global_batch\": 2") &&
                       Catch::Contains("\"allreduce_seconds\""));
  CHECK(fs::exists(dir / "run" / "checkpoints" / "latest.pt"));
}

namespace {

// The loss of a trunk's levels against fixed weights (the same for any split of the batch).
torch::Tensor trunk_loss(th::model::ResNetTrunk& trunk, const torch::Tensor& images,
                         const std::vector<torch::Tensor>& weights) {
  const auto levels = trunk->forward(images);
  auto loss = torch::zeros({}, torch::kFloat64);
  for (size_t l = 0; l < levels.size(); ++l)
    loss = loss + (levels[l].to(torch::kFloat64) * weights[l]).sum();
  return loss;
}

struct TrunkGrads {
  double loss = 0;
  std::map<std::string, torch::Tensor> params, buffers;
  torch::Tensor input;
};

TrunkGrads trunk_grads(th::model::ResNetTrunk& trunk, const torch::Tensor& images,
                       const std::vector<torch::Tensor>& weights) {
  auto x = images.clone().requires_grad_(true);
  const auto loss = trunk_loss(trunk, x, weights);
  loss.backward();
  TrunkGrads g;
  g.loss = loss.item<double>();
  for (const auto& p : trunk->named_parameters()) g.params[p.key()] = p.value().grad().clone();
  for (const auto& b : trunk->named_buffers())
    if (b.value().is_floating_point()) g.buffers[b.key()] = b.value().clone();
  g.input = x.grad().clone();
  return g;
}

}  // namespace

TEST_CASE(
    "synchronised BatchNorm: 2 ranks give the loss and gradients of one batch of both ranks' "
    "images",
    "[dist]") {
  torch::set_num_threads(1);
  const int64_t V = 3;  // reference images per rank
  torch::manual_seed(7);
  const auto images = torch::rand({2 * V, 3, 40, 48});
  th::model::ResNetTrunk probe(true);
  std::vector<torch::Tensor> weights;
  for (const auto& level : probe->forward(images.slice(0, 0, 1)))
    weights.push_back(
        torch::randn({2 * V, level.size(1), level.size(2), level.size(3)}, torch::kFloat64));
  auto make_trunk = [] {
    torch::manual_seed(11);
    th::model::ResNetTrunk t(true);
    t->train();
    return t;
  };
  auto slice = [&](const std::vector<torch::Tensor>& w, int r) {
    std::vector<torch::Tensor> out;
    for (const auto& t : w) out.push_back(t.slice(0, r * V, (r + 1) * V));
    return out;
  };

  // One process, one batch of all 2V images.
  auto whole = make_trunk();
  const TrunkGrads single = trunk_grads(whole, images, weights);

  // Two ranks (threads of this process, each with its own store connection and Gloo group),
  // each with V of the images.
  auto on_ranks = [&](bool sync) {
    const int port = th::dist::free_port();
    std::vector<TrunkGrads> out(2);
    std::vector<std::string> errors(2);
    std::vector<int> layers(2, 0);
    // Made here, one after the other: the seeded initialisation draws from one global generator.
    std::vector<th::model::ResNetTrunk> trunks{make_trunk(), make_trunk()};
    std::vector<std::thread> threads;
    for (int r = 0; r < 2; ++r)
      threads.emplace_back([&, r] {
        try {
          th::dist::Environment env;
          env.rank = r, env.world_size = 2, env.local_rank = r, env.master_port = port;
          th::dist::Communicator comm(env, "gloo", torch::kCPU, 60, 25);
          auto& trunk = trunks[size_t(r)];
          // (Catch's assertions are not thread-safe: results are checked after the join.)
          if (sync)
            layers[size_t(r)] = th::model::synchronise_batchnorm(
                *trunk, std::make_shared<const th::model::StatsReducer>([&comm](torch::Tensor& t) {
                  comm.sum_in_place(t, "test statistics");
                }));
          out[size_t(r)] =
              trunk_grads(trunk, images.slice(0, r * V, (r + 1) * V), slice(weights, r));
          comm.barrier("the end of the test");
        } catch (const std::exception& e) {
          errors[size_t(r)] = e.what();
        }
      });
    for (auto& t : threads) t.join();
    INFO(errors[0] << errors[1]);
    REQUIRE((errors[0].empty() && errors[1].empty()));
    CHECK(layers == std::vector<int>(2, sync ? 10 : 0));  // every BatchNorm of the trunk
    return out;
  };
  // The largest difference from the single batch: loss, parameter gradients (summed over the
  // ranks, as the gradient all-reduce does), input gradients, running statistics.
  auto difference = [&](const std::vector<TrunkGrads>& ranks) {
    double d = std::abs(ranks[0].loss + ranks[1].loss - single.loss) /
               std::max(1.0, std::abs(single.loss));
    for (const auto& [name, g] : single.params) {
      const auto sum = ranks[0].params.at(name) + ranks[1].params.at(name);
      d = std::max(d, ((sum - g).abs().max() / g.abs().max().clamp_min(1e-12)).item<double>());
    }
    const auto input = torch::cat({ranks[0].input, ranks[1].input});
    d = std::max(d, ((input - single.input).abs().max() / single.input.abs().max()).item<double>());
    for (const auto& [name, b] : single.buffers)
      for (const auto& rank : ranks)
        d = std::max(d, ((rank.buffers.at(name) - b).abs().max() / b.abs().max().clamp_min(1e-12))
                            .item<double>());
    return d;
  };
  const double synced = difference(on_ranks(true));
  INFO("relative difference with synchronised BatchNorm: " << synced);
  CHECK(synced <= 1e-5);
  // Control: each rank normalising its own images is another function (the check can fail).
  const double apart = difference(on_ranks(false));
  INFO("relative difference with per-rank BatchNorm: " << apart);
  CHECK(apart > 1e-3);
}

TEST_CASE("a killed rank makes the other exit with an error within the timeout, and 1 rank resumes",
          "[dist][slow]") {
  const double timeout = 10;
  const fs::path dir = th::test::scratch_dir("dist_kill");
  const int port = th::dist::free_port();
  const auto args =
      train_command(dir / "run", {},
                    tiny_overrides({"train.epochs=1000", "train.save_every_epochs=1",
                                    "train.dist_timeout_s=" + std::to_string(timeout)}));
  const Process r0 = start_rank(0, 2, port, args, dir / "rank0.log");
  const Process r1 = start_rank(1, 2, port, args, dir / "rank1.log");
  const bool trained = wait_for_file(dir / "run" / "checkpoints" / "epoch_0001.pt", r0, 120);
  INFO(th::test::read_text(dir / "rank0.log") + th::test::read_text(dir / "rank1.log"));
  if (!trained) {
    th::test::kill_and_reap(r0);
    th::test::kill_and_reap(r1);
  }
  REQUIRE(trained);

  th::test::kill_and_reap(r1);
  // The survivor must not wait forever: it ends (the wait below is a generous deadline, not a
  // timing check) with an orderly error that names the other rank and the timeout setting.
  const auto status = th::test::wait_for(r0, timeout + 60);
  if (!status) th::test::kill_and_reap(r0);
  REQUIRE(status.has_value());
  CHECK(describe(*status) == "exit 2");  // a reported error (3: internal error, signal: crash)
  const std::string log = th::test::read_text(dir / "rank0.log");
  CHECK_THAT(log, Catch::Contains("error") && Catch::Contains("rank 0 of 2"));
  CHECK_THAT(log, Catch::Contains("train.dist_timeout_s = " + std::to_string(int(timeout))));

  // The run continues from its last checkpoint with one rank.
  const auto c = tiny_config({"train.epochs=1000", "train.save_every_epochs=1"});
  const State saved = state_of(dir / "run" / "checkpoints" / "latest.pt", c);
  REQUIRE(saved.step >= 3);
  torch::set_num_threads(1);
  const auto resumed = th::train::train(c, torch::kCPU, {dir / "run", true, saved.step + 2});
  CHECK(resumed.steps == saved.step + 2);
  // Its metrics continue at the next step, with one rank.
  std::ifstream metrics(dir / "run" / "metrics.jsonl");
  std::string line, last;
  while (std::getline(metrics, line))
    if (!line.empty()) last = line;
  CHECK_THAT(last, Catch::Contains("\"step\": " + std::to_string(saved.step + 2)) &&
                       Catch::Contains("\"world_size\": 1"));
}

TEST_CASE("a hung rank makes the other exit with an error within the timeout", "[dist][slow]") {
  const double timeout = 5;
  const fs::path dir = th::test::scratch_dir("dist_hang");
  const int port = th::dist::free_port();
  const auto args = train_command(
      dir / "run", {},
      tiny_overrides({"train.epochs=1000", "train.dist_timeout_s=" + std::to_string(timeout)}));
  const Process r0 = start_rank(0, 2, port, args, dir / "rank0.log");
  const Process r1 = start_rank(1, 2, port, args, dir / "rank1.log");
  const bool training = wait_for_file(dir / "run" / "metrics.jsonl", r0, 120);
  INFO(th::test::read_text(dir / "rank0.log") + th::test::read_text(dir / "rank1.log"));
  if (!training) {
    th::test::kill_and_reap(r0);
    th::test::kill_and_reap(r1);
  }
  REQUIRE(training);
  ::kill(r1.pid, SIGSTOP);  // alive but not answering
  // As above: an orderly error naming the timeout, before a generous deadline.
  const auto status = th::test::wait_for(r0, timeout + 60);
  th::test::kill_and_reap(r1);
  if (!status) th::test::kill_and_reap(r0);
  REQUIRE(status.has_value());
  CHECK(describe(*status) == "exit 2");  // a reported error (3: internal error, signal: crash)
  const std::string log = th::test::read_text(dir / "rank0.log");
  CHECK_THAT(log, Catch::Contains("died or hung"));
  CHECK_THAT(log, Catch::Contains("train.dist_timeout_s = " + std::to_string(int(timeout))));
}

namespace {

// The children of `parent` (from /proc), and whether a process is still running (a zombie is not).
std::vector<pid_t> children_of(pid_t parent) {
  std::vector<pid_t> out;
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string name = e.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream stat(e.path() / "stat");
    std::string line;
    if (!std::getline(stat, line)) continue;
    // pid (comm) state ppid ...: comm may hold spaces, so read after its closing parenthesis.
    std::istringstream rest(line.substr(line.rfind(')') + 1));
    char state = 0;
    pid_t ppid = 0;
    if (rest >> state >> ppid && ppid == parent) out.push_back(pid_t(std::stol(name)));
  }
  return out;
}

bool running(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return false;
  std::istringstream rest(line.substr(line.rfind(')') + 1));
  char state = 0;
  rest >> state;
  return state != 'Z' && state != 'X';
}

bool all_gone(const std::vector<pid_t>& pids, double seconds) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < deadline) {
    bool any = false;
    for (pid_t p : pids) any = any || running(p);
    if (!any) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return false;
}

}  // namespace

TEST_CASE(
    "a stop signal to the --nproc launcher reaches every rank, and ranks die with a killed "
    "launcher",
    "[dist][slow]") {
  for (const int sig : {SIGTERM, SIGKILL}) {
    CAPTURE(sig);
    const fs::path dir = th::test::scratch_dir("dist_launcher_signal_" + std::to_string(sig));
    const auto args =
        train_command(dir / "run", {"--nproc", "2"}, tiny_overrides({"train.epochs=1000"}));
    const Process launcher = th::test::spawn(args, {}, dir / "launcher.log");
    const bool training = wait_for_file(dir / "run" / "metrics.jsonl", launcher, 120);
    const auto ranks = children_of(launcher.pid);
    INFO(th::test::read_text(dir / "launcher.log"));
    if (!training || ranks.size() != 2) {
      for (pid_t p : ranks) ::kill(p, SIGKILL);
      th::test::kill_and_reap(launcher);
    }
    REQUIRE(training);
    REQUIRE(ranks.size() == 2);
    ::kill(launcher.pid, sig);
    const auto status = th::test::wait_for(launcher, 60);
    if (!status) th::test::kill_and_reap(launcher);
    REQUIRE(status.has_value());
    const bool gone = all_gone(ranks, 30);
    if (!gone)
      for (pid_t p : ranks) ::kill(p, SIGKILL);
    CHECK(gone);
    if (sig == SIGTERM) {
      // The launcher waited for its ranks and says why it stopped.
      CHECK(describe(*status) == "exit " + std::to_string(128 + SIGTERM));
      CHECK_THAT(
          th::test::read_text(dir / "launcher.log"),
          Catch::Contains(
              "launcher: Terminated: passing it to the 2 running rank(s) and waiting for them"));
    } else {
      CHECK(describe(*status) == "signal " + std::to_string(SIGKILL));
    }
  }
}

namespace {

// The non-empty lines of `text`.
std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) out.push_back(line);
  return out;
}

}  // namespace

TEST_CASE("a user error only rank 0 sees ends every --nproc rank at once, its error line last",
          "[dist]") {
  // The others would wait train.dist_timeout_s for it at the rendezvous: far longer than the
  // generous deadline below.
  const fs::path dir = th::test::scratch_dir("dist_rank0_error");
  fs::create_directories(dir / "run");
  std::ofstream(dir / "run" / "notes.txt") << "someone else's\n";  // only rank 0 claims --out
  const auto args =
      train_command(dir / "run", {"--nproc", "2"}, tiny_overrides({"train.dist_timeout_s=600"}));
  const auto t0 = std::chrono::steady_clock::now();
  const Process launcher = th::test::spawn(args, {}, dir / "launcher.log");
  const auto status = th::test::wait_for(launcher, 60);
  if (!status) th::test::kill_and_reap(launcher);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string log = th::test::read_text(dir / "launcher.log");
  INFO(log);
  REQUIRE(status.has_value());
  CHECK(describe(*status) == "exit 2");
  CHECK(seconds < 60);
  const auto lines = lines_of(log);
  REQUIRE_FALSE(lines.empty());
  CHECK_THAT(lines.back(), Catch::StartsWith("transhuman-train[rank 0]: error: --out '") &&
                               Catch::Contains("already holds 1 entr") &&
                               Catch::Contains("(notes.txt)"));
  size_t errors = 0;
  for (const auto& line : lines) errors += line.find("error:") != std::string::npos;
  CHECK(errors == 1);  // neither rank 1's rendezvous error nor "a rank failed"
  CHECK(log.find("c10d") == std::string::npos);
  CHECK(th::test::read_text(dir / "run" / "notes.txt") == "someone else's\n");
}

TEST_CASE("the launcher reports the rank's own error, not the others' that follow from it",
          "[dist]") {
  // Rank 1 reports that rank 0 went away and ends first; rank 0's own error comes later: it is
  // the last line. A rank killed without a word is named by the launcher.
  const fs::path dir = th::test::scratch_dir("dist_launcher_lines");
  const std::string script =
      "if [ \"$RANK\" = 0 ]; then sleep 0.5; echo 'w[rank 0]: error: the real cause' >&2; exit 2; "
      "fi; "
      "echo 'w[rank 1]: error: rank 1 of 2: broadcasting the frames failed: Connection closed' "
      ">&2; exit 2";
  const int saved = ::dup(2);
  const fs::path log = dir / "launcher.log";
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  ::dup2(fd, 2);
  std::string failure = "unset";
  th::dist::LaunchOptions options;
  options.nproc = 2;
  const int code = th::dist::launch_local({"/bin/sh", "-c", script}, options, &failure);
  ::dup2(saved, 2);
  ::close(fd);
  ::close(saved);
  const std::string text = th::test::read_text(log);
  INFO(text);
  CHECK(code == 2);
  CHECK(failure.empty());
  const auto lines = lines_of(text);
  REQUIRE_FALSE(lines.empty());
  CHECK(lines.back() == "w[rank 0]: error: the real cause");
  CHECK(text.find("Connection closed") == std::string::npos);

  options.nproc = 2;
  const auto t0 = std::chrono::steady_clock::now();
  const int killed = th::dist::launch_local(
      {"/bin/sh", "-c", "if [ \"$RANK\" = 1 ]; then kill -9 $$; fi; exec sleep 100"}, options,
      &failure);
  CHECK(killed == 128 + SIGKILL);
  CHECK(failure == "rank 1 was killed by signal 9 (Killed)");
  CHECK(std::chrono::steady_clock::now() - t0 <
        std::chrono::seconds(30));  // rank 0 stopped, not waited for
}
