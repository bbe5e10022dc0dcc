// transhuman-render: free-viewpoint video of a person from a trained checkpoint (METHOD 7), in one
// process or over several ranks (--nproc N, or a launcher's environment): frames split, rank 0
// writes them.
#include <spdlog/spdlog.h>

#include <iostream>
#include <optional>

#include "app/app.hpp"
#include "app/ranks.hpp"
#include "app/summary.hpp"
#include "bake/bake.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/resources.hpp"
#include "inference/free_view.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main(th::app::rank_app_name("transhuman-render"), [&]() -> int {
    CLI::App cli{
        "Render free-viewpoint video of a person with a trained TransHuman checkpoint.\n"
        "Cameras: the orbit of METHOD 7 (default, 36 views), a camera path file (--path) or\n"
        "one dataset camera (--camera). Writes frames/*.png, video.mp4 (30 fps),\n"
        "cameras.yaml and contact_sheet.png into --out; rerunning resumes."};
    th::app::CommonOptions options;
    th::inference::VideoRequest request;
    th::app::ModelOptions model;
    std::string frames;
    int nproc = 0;
    th::app::add_common_options(cli, options);
    th::app::add_model_options(cli, model);
    th::app::add_precision_option(cli, options);
    cli.add_option("--human", request.human, "person (folder name); default: the setting's first");
    cli.add_option("--frames", frames,
                   "body frame(s): F, BEGIN:END or BEGIN:END:STEP (default: the setting's first)");
    auto* orbit = cli.add_option("--orbit", request.orbit_views,
                                 "orbit with N views (default 36, or one per frame of a range)")
                      ->check(th::app::at_least(1));
    auto* path =
        cli.add_option("--path", request.path_file, "camera path file (YAML/JSON, see README)");
    auto* camera =
        cli.add_option("--camera", request.camera,
                       "render from this dataset camera (its name or calibration index)");
    orbit->excludes(path)->excludes(camera);
    path->excludes(camera);
    cli.add_option("--view", request.view,
                   "camera whose intrinsics and image size the orbit uses (METHOD 7: 3)")
        ->check(th::app::at_least(0));
    cli.add_option("--width", request.width, "output width (default: the view's at data.ratio)")
        ->check(th::app::at_least(1));
    cli.add_option("--height", request.height, "output height")->check(th::app::at_least(1));
    bool baked = false;
    th::bake::BakeOptions bake;
    std::filesystem::path bake_in, bake_out;
    cli.add_flag("--baked", baked,
                 "render from the frame baked to a sparse grid (METHOD 7.1): a bake per body "
                 "frame, then every view in milliseconds, a little less exact");
    auto* bake_voxel =
        cli.add_option("--bake-voxel", bake.voxel,
                       "bake: grid spacing in metres (default 0.02; with --baked or --bake-in)")
            ->check(th::app::in_range(0.001, 0.2));
    cli.add_option("--bake-in", bake_in,
                   "bake: read this baked frame (written by --bake-out) instead of baking; "
                   "implies --baked")
        ->check(CLI::ExistingFile);
    cli.add_option("--bake-out", bake_out,
                   "bake: also write the (one) body frame's bake to this new file");
    th::app::add_force_option(
        cli, options,
        "replace what --out holds: frames of an earlier, different request, or another "
        "command's outputs");
    th::app::add_nproc_option(cli, nproc, "split the frames");
    options.own_outputs = {"config.yaml",  "log.txt",   "frames",           "request.yaml",
                           "cameras.yaml", "video.mp4", "contact_sheet.png"};
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    th::app::apply_model_options(model, options);
    if (!bake_in.empty()) baked = true;
    if (*bake_voxel && !baked)
      th::fail("--bake-voxel sets the grid of a bake: it needs --baked (or --bake-in)");
    if (!bake_out.empty() && !baked) th::fail("--bake-out needs --baked");
    if (!bake_in.empty()) th::refuse_special_file(bake_in, "--bake-in");
    options.inputs.push_back({"the baked frame (--bake-in)", bake_in});
    request.force = options.force;
    options.inputs.push_back({"the camera path (--path)", request.path_file});
    if (!frames.empty()) request.frames = th::inference::parse_frame_range(frames);
    if (*path) request.cameras = th::inference::VideoRequest::Cameras::PathFile;
    if (*camera) request.cameras = th::inference::VideoRequest::Cameras::Dataset;

    if (const auto code =
            th::app::launch_ranks(nproc, options, argc, argv, "transhuman-render", "runs/render"))
      return *code;
    const auto role = th::app::rank_role(options);
    // The bake's destination is the lead's to write: checked before anything is written, and
    // against the config's inputs (the data root) once it is read.
    const std::string out_dir = options.out.empty() ? "runs/render" : options.out;
    if (!bake_out.empty() && role.lead)
      th::bake::check_bake_destination(bake_out, "--bake-out", {{"--out", out_dir}});
    const auto ctx =
        th::app::start_run(options, "transhuman-render", role.lead ? "runs/render" : "");
    th::app::share_cores(role, ctx);
    if (role.lead) th::app::print_summary(ctx, options.dry_run, model.checkpoint);
    // The bake file whole, checked before the model is loaded.
    std::optional<th::bake::BakedFrame> baked_file;
    if (!bake_in.empty()) {
      baked_file = th::bake::read_baked(
          bake_in, th::resources::memory_limit_bytes(ctx.config.max_memory_gb));
      if (*bake_voxel && baked_file->voxel != bake.voxel)
        th::fail("--bake-voxel ", bake.voxel, ": baked frame '", bake_in.string(),
                 "' has its own grid of ", baked_file->voxel, " m (leave --bake-voxel out)");
    }
    if (!bake_out.empty() && role.lead) {
      auto places = th::app::config_inputs(ctx.config, options.config);
      places.insert(places.end(), options.inputs.begin(), options.inputs.end());
      places.push_back({"--out", out_dir});
      th::bake::check_bake_destination(bake_out, "--bake-out", places);
    }
    const th::inference::Session session(ctx.config, ctx.device, model.checkpoint);
    std::optional<th::inference::VideoPlan> plan;
    if (options.dry_run || baked) plan = th::inference::plan_video(session, request);
    std::unique_ptr<th::bake::BakedViews> views;
    if (baked) {
      views = std::make_unique<th::bake::BakedViews>(session, bake);
      if ((!bake_in.empty() || !bake_out.empty()) && plan->frames.size() != 1)
        th::fail("--bake-in and --bake-out take one body frame; --frames names ",
                 plan->frames.size());
      if (baked_file) views->use(std::move(*baked_file), plan->prepared);
    }
    if (options.dry_run) {  // the request too: person, frames, cameras, path file, memory, bake
      if (baked && bake_in.empty())
        th::bake::check_bake_memory(
            th::bake::bake_box(plan->prepared.sample.body.bounds), bake, session,
            fmt::format("{} frame {}", plan->human_name, plan->frames.front()));
      spdlog::info("dry run: a video of {} frames of {} ({} body frame{}), {}x{}", plan->count,
                   plan->human_name, plan->frames.size(), plan->frames.size() > 1 ? "s" : "",
                   plan->width, plan->height);
      return 0;
    }
    if (baked) {
      const auto& b = views->bake(plan->prepared);
      if (bake_in.empty()) {
        const auto& r = views->last_report();
        spdlog::info(
            "bake: {} frame {} in {:.2f} s (coarse {:.2f}, fine {:.2f}, colour {:.2f}, "
            "pack {:.2f}); points: {} coarse, {} fine, {} coloured; {} bricks, {:.1f} MiB",
            b.human, b.frame, r.total_seconds(), r.seconds.at("coarse"), r.seconds.at("fine"),
            r.seconds.at("colour"), r.seconds.at("pack"), r.coarse_points, r.fine_points,
            r.color_points, b.stored_bricks(), b.bytes() / 1048576.0);
      }
      if (!bake_out.empty() && role.lead) {
        th::bake::write_baked(b, bake_out);
        spdlog::info("bake: written to {}", bake_out.string());
      }
      request.renderer = [&views](const th::inference::PreparedFrame& frame,
                                  const th::video::PathCamera& camera, int width, int height) {
        return views->render(frame, camera, width, height);
      };
      request.renderer_id = views->id();
      request.renderer_keys = views->request_keys();
    }
    const auto comm = th::app::join_ranks(role, ctx);
    const auto s = th::inference::render_video(session, request, ctx.run_dir, comm.get());
    if (!role.lead) return 0;
    spdlog::info("{} frames ({} rendered, {} resumed), {:.2f} s/frame, in {}", s.frames, s.rendered,
                 s.skipped, s.seconds_per_frame, s.frames_dir.string());
    if (s.video_written)
      spdlog::info("{}", s.video_message);
    else
      spdlog::warn("{}", s.video_message);
    if (!s.contact_sheet.empty()) spdlog::info("contact sheet: {}", s.contact_sheet.string());
    return 0;
  });
}
