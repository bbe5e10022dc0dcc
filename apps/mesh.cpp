// transhuman-mesh: a triangle mesh of a person from a trained checkpoint's density (METHOD 7).
#include <spdlog/spdlog.h>

#include "app/app.hpp"
#include "app/summary.hpp"
#include "inference/mesh_extraction.hpp"

int main(int argc, char** argv) {
  return th::app::guarded_main("transhuman-mesh", [&]() -> int {
    CLI::App cli{
        "Extract a mesh of a person from a trained TransHuman checkpoint: density on a grid\n"
        "over the frame's box, marching cubes, binary PLY and a preview PNG in --out."};
    th::app::CommonOptions options;
    th::inference::MeshRequest request;
    th::app::ModelOptions model;
    th::app::add_common_options(cli, options);
    th::app::add_model_options(cli, model);
    th::app::add_precision_option(cli, options);
    cli.add_option("--human", request.human, "person (folder name); default: the setting's first");
    cli.add_option("--frame", request.frame,
                   "body frame (annots index); default: the setting's first")
        ->check(th::app::at_least(0));
    cli.add_option("--voxel", request.voxel, "grid spacing in metres (METHOD 7: 0.005)")
        ->check(th::app::above(0));
    cli.add_option("--threshold", request.threshold,
                   "marching-cubes level on raw density, >= 0 (METHOD 7: 20)")
        ->check(th::app::at_least(0));
    cli.add_flag("--colors", request.colors, "vertex colours from the colour branch");
    cli.add_option("--view", request.view, "the preview looks from this camera (and from its side)")
        ->check(th::app::at_least(0));
    th::app::add_force_option(cli, options);
    options.own_outputs = {"config.yaml", "log.txt", "*.ply", "*_preview.png"};
    if (const auto rc = th::app::parse_command_line(cli, argc, argv)) return *rc;
    th::app::apply_model_options(model, options);

    const auto ctx = th::app::start_run(options, "transhuman-mesh", "runs/mesh");
    th::app::print_summary(ctx, options.dry_run, model.checkpoint);
    const th::inference::Session session(ctx.config, ctx.device, model.checkpoint);
    if (options.dry_run) {  // the request too: person, frame, view, grid and its memory
      const auto plan = th::inference::plan_mesh(session, request);
      spdlog::info("dry run: a {} x {} x {} grid over {} frame {}", plan.grid[0], plan.grid[1],
                   plan.grid[2], session.human(plan.human).name(), plan.frame);
      return 0;
    }
    const auto s = th::inference::extract_mesh(session, request, ctx.run_dir);
    spdlog::info("mesh {} ({} vertices, {} faces), preview {}", s.ply.string(), s.mesh.num_verts(),
                 s.mesh.num_faces(), s.preview.string());
    return 0;
  });
}
