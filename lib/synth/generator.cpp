#include "synth/generator.hpp"

#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/core/persistence.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "body/smpl.hpp"
#include "core/error.hpp"
#include "core/files.hpp"
#include "core/progress.hpp"
#include "core/runtime.hpp"
#include "geometry/camera.hpp"
#include "geometry/mesh.hpp"
#include "io/npy.hpp"
#include "synth/body_builder.hpp"
#include "synth/layout.hpp"
#include "synth/motion.hpp"
#include "synth/person.hpp"
#include "synth/png.hpp"
#include "synth/render.hpp"
#include "synth/rig.hpp"
#include "synth/split.hpp"

namespace th::synth {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
constexpr const char* kConfigFile = "synth_config.yaml";

// Runs fn(0..n-1) on `threads` workers; the first exception is rethrown after all stop.
void parallel_for(int64_t n, int threads, const std::function<void(int64_t)>& fn) {
  std::atomic<int64_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&] {
    for (int64_t i = next++; i < n; i = next++) {
      try {
        fn(i);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        next = n;
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

// LibTorch's, OpenBLAS's and OpenCV's own thread pools are set to one thread while the workers
// run (they are the parallelism; OpenBLAS's threads would spin between the small matrix products
// of LBS and take a third of the CPU); restored afterwards.
class LibraryThreads {
 public:
  explicit LibraryThreads(int n) : torch_and_blas_(n), cv_(cv::getNumThreads()) {
    cv::setNumThreads(n);
  }
  ~LibraryThreads() { cv::setNumThreads(cv_); }

 private:
  runtime::ScopedThreads torch_and_blas_;
  int cv_;
};

// Every file through a new temporary file renamed over the target (never through a link).
void write_bytes(const fs::path& path, const std::vector<uchar>& bytes) {
  write_file_atomic(path,
                    std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

void write_bytes(const fs::path& path, const std::string& bytes) { write_file_atomic(path, bytes); }

void write_image(const fs::path& path, const cv::Mat& image, const std::vector<int>& params) {
  std::vector<uchar> bytes;
  if (!cv::imencode(path.extension().string(), image, bytes, params))
    fail("cannot encode '", path.string(), "'");
  write_bytes(path, bytes);
}

io::Value array_value(const torch::Tensor& t) { return io::Value::array(t.contiguous()); }

torch::Tensor row(const std::array<double, 3>& v) {
  return torch::tensor({v[0], v[1], v[2]}, torch::kFloat64);
}

// EasyMocap's layout (data/easymocap.hpp): cameras named by calibration index ("00".."22"), so
// that the split file's indices and the names agree (data::camera_index refuses a number that
// names one camera and indexes another), frames numbered from 0 with six digits.
std::string easymocap_camera(int camera) {
  char name[16];
  std::snprintf(name, sizeof name, "%02d", camera);
  return name;
}

std::string easymocap_frame(int frame) {
  char name[16];
  std::snprintf(name, sizeof name, "%06d", frame);
  return name;
}

std::vector<double> values(const torch::Tensor& t) {
  const auto c = t.to(torch::kFloat64).contiguous();
  return std::vector<double>(c.data_ptr<double>(), c.data_ptr<double>() + c.numel());
}

// One frame's fit as EasyMocap writes it: a list of people (one here, id 0). nlohmann writes
// doubles with the digits that read back to the same value.
std::string easymocap_smpl(const torch::Tensor& poses, const torch::Tensor& Rh,
                           const torch::Tensor& Th, const torch::Tensor& shapes) {
  nlohmann::ordered_json person;
  person["id"] = 0;
  person["Rh"] = {values(Rh)};
  person["Th"] = {values(Th)};
  person["poses"] = {values(poses)};
  person["shapes"] = {values(shapes)};
  return nlohmann::ordered_json::array({person}).dump() + "\n";
}

cv::Mat cv_matrix(const torch::Tensor& t, int rows, int cols) {
  const auto v = values(t);
  return cv::Mat(rows, cols, CV_64F, const_cast<double*>(v.data())).clone();
}

// intri.yml and extri.yml of one person, holding what the ZJU-MoCap reader makes of annots.npy
// (T through millimetres and back), so both layouts of a person read the same.
void write_easymocap_calibration(const fs::path& dir, const FolderLayout& l,
                                 const std::vector<CameraCalib>& cameras) {
  std::vector<std::string> names;
  for (int k = 0; k < l.num_cameras(); ++k) names.push_back(easymocap_camera(k));
  for (const char* file : {"intri.yml", "extri.yml"}) {
    const bool intri = std::string(file) == "intri.yml";
    cv::FileStorage out(".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
    out << "names" << names;
    for (size_t k = 0; k < cameras.size(); ++k) {
      const CameraCalib& cam = cameras[k];
      if (intri) {
        out << "K_" + names[k] << cv_matrix(cam.K, 3, 3);
        out << "dist_" + names[k] << cv_matrix(cam.D, 1, 5);
      } else {
        const torch::Tensor T = (cam.T * 1000.0).to(torch::kFloat64) / 1000.0;
        out << "R_" + names[k] << cv_matrix(geometry::axis_angle(cam.R.to(torch::kFloat64)), 3, 1);
        out << "Rot_" + names[k] << cv_matrix(cam.R, 3, 3);
        out << "T_" + names[k] << cv_matrix(T, 3, 1);
      }
    }
    write_bytes(dir / file, out.releaseAndGetString());
  }
}

// Everything about one person that the frame tasks share.
struct Recording {
  Person person;
  FolderLayout layout{"", FolderStyle::Standard, {}};
  std::vector<CameraCalib> cameras;
  std::vector<StudioView> views;
  Motion motion;
  std::vector<FrameParams> published;  // motion + fitting noise (Th z from the true pose)
  torch::Tensor published_shapes;      // (10)
};

// Published = true parameters + a fitting error (the fitted body is not exact).
FrameParams add_noise(const FrameParams& truth, const SynthNoiseConfig& n, Rng& rng) {
  FrameParams out = truth;
  if (!n.enabled) return out;
  for (int i = 3; i < 72; ++i) out.poses[i] += rng.normal(0.0, n.pose_std);
  auto noise = geometry::rodrigues(torch::tensor(
      {rng.normal(0.0, n.rh_std), rng.normal(0.0, n.rh_std), rng.normal(0.0, n.rh_std)},
      torch::kFloat64));
  auto rh = geometry::axis_angle(torch::matmul(noise, geometry::rodrigues(row(truth.Rh))));
  for (int c = 0; c < 3; ++c) out.Rh[c] = rh[c].item<double>();
  for (int c = 0; c < 3; ++c) out.Th[c] += rng.normal(0.0, n.th_std);
  return out;
}

// Contact sheet: for each person a row of tiles over frames and views.
constexpr int kSheetColumns = 8;
constexpr int kTile = 160;
std::pair<int, int> sheet_cell(int column, int frames, int cameras) {
  static const int views[kSheetColumns] = {0, 3, 7, 10, 12, 15, 18, 20};
  const int frame = kSheetColumns > 1 ? column * (frames - 1) / (kSheetColumns - 1) : 0;
  return {frame, std::min(views[column], cameras - 1)};
}

void remove_dataset(const fs::path& out, const SynthConfig& c) {
  std::vector<std::string> names = c.people.train;
  names.insert(names.end(), c.people.unseen.begin(), c.people.unseen.end());
  for (const auto& n : names) fs::remove_all(out / n);
  for (const char* f :
       {"smpl_model.npz", "smpl_model.pkl", "split.yaml", "contact_sheet.png", kConfigFile})
    fs::remove(out / f);
}

int64_t folder_bytes(const fs::path& dir) {
  int64_t total = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) total += int64_t(e.file_size());
  return total;
}

}  // namespace

Summary generate(const SynthConfig& c, const fs::path& out, bool force) {
  config::check(c, "");
  const auto start = Clock::now();
  Summary summary;
  const std::string text = config_text(c);

  // Refuse to mix datasets: an existing folder must be this very dataset (then skip) or empty.
  if (fs::exists(out)) {
    if (!fs::is_directory(out)) fail("output '", out.string(), "' exists and is not a folder");
    const fs::path cfg = out / kConfigFile;
    if (fs::exists(cfg)) {
      std::string existing;
      {
        std::ifstream f(cfg);
        existing.assign(std::istreambuf_iterator<char>(f), {});
      }
      if (existing == text && !force) {
        summary.skipped = true;
        summary.bytes = folder_bytes(out);
        return summary;
      }
      if (!force)
        fail("output '", out.string(), "' holds a synthetic dataset made with a different ",
             "config (", cfg.string(), "); use --force to replace it");
      try {
        remove_dataset(out, config::load<SynthConfig>(cfg));
      } catch (const Error&) {
        // An unreadable old config: remove what the new one would write.
      }
      remove_dataset(out, c);
    } else if (!fs::is_empty(out)) {
      if (!force)
        fail("output '", out.string(), "' is not empty and holds no finished synthetic dataset (",
             kConfigFile, " is missing); use --force to write into it");
      remove_dataset(out, c);
    }
  }
  fs::create_directories(out);
  LibraryThreads library_threads(1);

  // The body model (METHOD 1.5), written in both formats. Its pose blend shapes are zero and
  // are stored as float32, which halves the largest array (readers convert to float64).
  const BodyTemplate body = build_body_template();
  body::SmplModel stored = body.model;
  stored.posedirs = stored.posedirs.to(torch::kFloat32);
  body::save_smpl_npz(out / "smpl_model.npz", stored);
  body::save_smpl_pkl(out / "smpl_model.pkl", stored);

  // People, rigs, motion and noise, drawn serially from their own random streams.
  const uint64_t seed = static_cast<uint64_t>(c.seed);
  Rng studio_rng = Rng::stream(seed, 1);
  const auto ring = make_ring(c.cameras, c.image.width, c.image.height, studio_rng);
  std::vector<std::string> names = c.people.train;
  names.insert(names.end(), c.people.unseen.begin(), c.people.unseen.end());
  const int P = int(names.size());
  std::vector<Recording> recs(P);
  const uint64_t style_offset = Rng::stream(seed, 2).below(60);
  for (int i = 0; i < P; ++i) {
    Recording& r = recs[i];
    const bool unseen = i >= int(c.people.train.size());
    Rng person_rng = Rng::stream(seed, 100 + i);
    r.person = make_person(body, names[i], i, unseen, c.people.shape_std, style_offset, person_rng);
    r.person.folders = FolderLayout::style_for(names[i]);
    r.person.masks = static_cast<MaskStyle>(i % 3);
    std::vector<int> idx = r.person.folders == FolderStyle::Original21 ? cameras_21(c.cameras.count)
                                                                       : std::vector<int>();
    if (idx.empty())
      for (int k = 0; k < c.cameras.count; ++k) idx.push_back(k);
    r.layout = FolderLayout(names[i], r.person.folders, idx);
    Rng rig_rng = Rng::stream(seed, 200 + i);
    r.cameras = recalibrate(ring, idx, c.cameras, rig_rng);
    Rng motion_rng = Rng::stream(seed, 300 + i);
    r.motion = make_motion(c.frames, motion_rng);
    Rng noise_rng = Rng::stream(seed, 400 + i);
    r.published_shapes = r.person.shapes.clone();
    if (c.noise.enabled && c.noise.shape_std > 0)
      for (int k = 0; k < kNumBetas; ++k)
        r.published_shapes[k] += noise_rng.normal(0.0, c.noise.shape_std);
    for (const auto& f : r.motion.frames) r.published.push_back(add_noise(f, c.noise, noise_rng));
    r.views.resize(r.cameras.size());
  }

  // Lens distortion maps per ring camera, then studio views per person and camera.
  std::vector<std::pair<cv::Mat, cv::Mat>> lens(ring.size());
  parallel_for(int64_t(ring.size()), c.threads, [&](int64_t k) {
    lens[k] = geometry::distortion_maps(ring[k].K, ring[k].D, c.image.width, c.image.height);
  });
  std::vector<std::pair<int, int>> view_jobs;
  for (int i = 0; i < P; ++i)
    for (int k = 0; k < int(recs[i].cameras.size()); ++k) view_jobs.emplace_back(i, k);
  parallel_for(int64_t(view_jobs.size()), c.threads, [&](int64_t j) {
    auto [i, k] = view_jobs[j];
    recs[i].views[k] = make_studio_view(recs[i].cameras[k], lens[recs[i].layout.ring_index()[k]],
                                        c.image.width, c.image.height);
  });

  // Frames: pose, publish params and vertices, render every camera.
  std::map<std::pair<int, int>, cv::Mat> tiles;  // (person, column) -> tile
  std::mutex mutex;
  Progress progress("synth", int64_t(P) * c.frames, "frame");
  const std::vector<int> jpeg = {cv::IMWRITE_JPEG_QUALITY, c.image.jpeg_quality,
                                 cv::IMWRITE_JPEG_OPTIMIZE, 1};
  const std::vector<int> png = {cv::IMWRITE_PNG_COMPRESSION, 6};
  const bool easymocap = c.layout == "easymocap";
  for (int i = 0; i < P; ++i) {
    const fs::path dir = out / names[i];
    const FolderLayout& l = recs[i].layout;
    if (easymocap) {
      for (int k = 0; k < l.num_cameras(); ++k) {
        fs::create_directories(dir / "images" / easymocap_camera(k));
        fs::create_directories(dir / "mask" / easymocap_camera(k));
      }
      fs::create_directories(dir / "output" / "smpl");
      continue;
    }
    for (int k = 0; k < l.num_cameras(); ++k) {
      fs::create_directories(dir / l.camera_folder(k));
      if (recs[i].person.masks != MaskStyle::Cihp)
        fs::create_directories(dir / "mask" / l.camera_folder(k));
      if (recs[i].person.masks != MaskStyle::Mask)
        fs::create_directories(dir / "mask_cihp" / l.camera_folder(k));
    }
    fs::create_directories(dir / fs::path(l.params_path(0)).parent_path());
    fs::create_directories(dir / fs::path(l.vertices_path(0)).parent_path());
  }
  parallel_for(int64_t(P) * c.frames, c.threads, [&](int64_t job) {
    const int i = int(job / c.frames), f = int(job % c.frames);
    Recording& r = recs[i];
    const fs::path dir = out / names[i];
    const FrameParams& truth = r.motion.frames[f];
    FrameParams pub = r.published[f];

    // True pose: skin the render mesh, stand it on the floor (z = 0).
    const auto fit = body::lbs(
        body.model,
        torch::tensor(std::vector<double>(truth.poses.begin(), truth.poses.end()), torch::kFloat64),
        r.person.shapes);
    auto posed = body::skin_points(r.person.mesh.rest, r.person.mesh.weights, fit.G);
    auto world = body::smpl_to_world(posed, row(truth.Rh), row(truth.Th));
    const double lift = -world.select(1, 2).min().item<double>();
    world.select(1, 2).add_(lift);
    pub.Th[2] += lift;
    PosedMesh pm{world, geometry::vertex_normals(world, r.person.mesh.faces), &r.person.mesh,
                 &r.person.materials};

    // Published fit (with noise): params and the body model's vertices for them.
    auto poses =
        torch::tensor(std::vector<double>(pub.poses.begin(), pub.poses.end()), torch::kFloat64);
    const auto fitted = body::lbs(body.model, poses, r.published_shapes);
    auto verts = body::smpl_to_world(fitted.vertices, row(pub.Rh), row(pub.Th));
    if (easymocap) {
      write_bytes(dir / "output" / "smpl" / (easymocap_frame(f) + ".json"),
                  easymocap_smpl(poses, row(pub.Rh), row(pub.Th), r.published_shapes));
    } else {
      io::Value::Dict params;
      params.emplace_back(io::Value::str("poses"), array_value(poses.reshape({1, 72})));
      params.emplace_back(io::Value::str("Rh"), array_value(row(pub.Rh).reshape({1, 3})));
      params.emplace_back(io::Value::str("Th"), array_value(row(pub.Th).reshape({1, 3})));
      params.emplace_back(io::Value::str("shapes"),
                          array_value(r.published_shapes.reshape({1, kNumBetas})));
      io::write_npy_value(dir / r.layout.params_path(f), io::Value::dict(std::move(params)));
      io::write_npy(dir / r.layout.vertices_path(f), verts.to(torch::kFloat32));
    }

    const double gx = truth.Th[0], gy = truth.Th[1];
    for (int k = 0; k < r.layout.num_cameras(); ++k) {
      const RenderedView v =
          render_view(pm, r.views[k], c.image.width, c.image.height, c.image.supersample, gx, gy);
      const std::string camera = easymocap_camera(k), frame = easymocap_frame(f);
      write_image(
          easymocap ? dir / "images" / camera / (frame + ".jpg") : dir / r.layout.image_path(f, k),
          v.bgr, jpeg);
      cv::Mat coverage = v.alpha > 0.5f;  // 255 where covered
      cv::Mat mask = coverage / 255;      // ZJU-MoCap masks are 0/1
      if (easymocap) {
        // One mask, 0/255: what the ZJU-MoCap reader makes of mask/ and mask_cihp/ together.
        cv::Mat person;
        if (r.person.masks == MaskStyle::Both) {
          cv::Mat missed = (v.labels == cihp::kHair) | (v.labels == cihp::kLeftShoe) |
                           (v.labels == cihp::kRightShoe);
          mask.setTo(0, missed);
          person = (mask != 0) | ((v.labels != 0) & (v.alpha > 0.75f));
        } else if (r.person.masks == MaskStyle::Mask) {
          person = mask != 0;
        } else {
          person = (v.labels != 0) & coverage;
        }
        write_bytes(dir / "mask" / camera / (frame + ".png"), encode_mask_png(person));
      } else if (r.person.masks == MaskStyle::Both) {
        // Two parsers that each miss something: the matting misses hair and shoes, the part
        // parser is tighter at the edges; the loader's union restores the person (METHOD 2.1).
        cv::Mat missed = (v.labels == cihp::kHair) | (v.labels == cihp::kLeftShoe) |
                         (v.labels == cihp::kRightShoe);
        mask.setTo(0, missed);
        cv::Mat labels = v.labels.clone();
        labels.setTo(0, v.alpha <= 0.75f);
        write_bytes(dir / r.layout.mask_path("mask", f, k), encode_mask_png(mask));
        write_bytes(dir / r.layout.mask_path("mask_cihp", f, k), encode_mask_png(labels));
      } else if (r.person.masks == MaskStyle::Mask) {
        write_bytes(dir / r.layout.mask_path("mask", f, k), encode_mask_png(mask));
      } else {
        cv::Mat labels = v.labels.clone();
        labels.setTo(0, ~coverage);
        write_bytes(dir / r.layout.mask_path("mask_cihp", f, k), encode_mask_png(labels));
      }
      if (c.contact_sheet)
        for (int col = 0; col < kSheetColumns; ++col)
          if (sheet_cell(col, c.frames, r.layout.num_cameras()) == std::pair{f, k}) {
            cv::Mat tile;
            cv::resize(v.bgr, tile, {kTile, kTile * c.image.height / c.image.width}, 0, 0,
                       cv::INTER_AREA);
            std::lock_guard<std::mutex> lock(mutex);
            tiles[{i, col}] = tile;
          }
    }
    std::lock_guard<std::mutex> lock(mutex);
    progress.advance(1);
  });
  progress.finish();

  // annots.npy per person (METHOD 1.1): cams {K, R, T (mm), D} and ims [{ims: [paths]}].
  for (int i = 0; i < P; ++i) {
    const Recording& r = recs[i];
    summary.lines.push_back(names[i] + (r.person.unseen ? " (unseen)" : "") + ": " +
                            std::to_string(r.layout.num_cameras()) + " cameras; " +
                            r.person.description + "; motion: " + r.motion.script);
    if (easymocap) {
      write_easymocap_calibration(out / names[i], r.layout, r.cameras);
      continue;
    }
    io::Value::List K, R, T, D, ims;
    for (const auto& cam : r.cameras) {
      K.push_back(array_value(cam.K));
      R.push_back(array_value(cam.R));
      T.push_back(array_value(cam.T * 1000.0));
      D.push_back(array_value(cam.D));
    }
    for (int f = 0; f < c.frames; ++f) {
      io::Value::List paths;
      for (int k = 0; k < r.layout.num_cameras(); ++k)
        paths.push_back(io::Value::str(r.layout.image_path(f, k)));
      io::Value::Dict entry;
      entry.emplace_back(io::Value::str("ims"), io::Value::list(std::move(paths)));
      ims.push_back(io::Value::dict(std::move(entry)));
    }
    io::Value::Dict cams;
    cams.emplace_back(io::Value::str("K"), io::Value::list(std::move(K)));
    cams.emplace_back(io::Value::str("R"), io::Value::list(std::move(R)));
    cams.emplace_back(io::Value::str("T"), io::Value::list(std::move(T)));
    cams.emplace_back(io::Value::str("D"), io::Value::list(std::move(D)));
    io::Value::Dict annots;
    annots.emplace_back(io::Value::str("cams"), io::Value::dict(std::move(cams)));
    annots.emplace_back(io::Value::str("ims"), io::Value::list(std::move(ims)));
    io::write_npy_value(out / names[i] / "annots.npy", io::Value::dict(std::move(annots)));
  }

  write_bytes(out / "split.yaml", split_yaml(c));

  if (c.contact_sheet) {
    const int th = kTile * c.image.height / c.image.width;
    cv::Mat sheet(th * P, kTile * kSheetColumns, CV_8UC3, cv::Scalar::all(0));
    for (const auto& [key, tile] : tiles)
      tile.copyTo(sheet(cv::Rect(key.second * kTile, key.first * th, tile.cols, tile.rows)));
    for (int i = 0; i < P; ++i) {
      const std::string label = names[i] + (recs[i].person.unseen ? " (unseen)" : "");
      cv::putText(sheet, label, {4, i * th + 14}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                  cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
    }
    write_image(out / "contact_sheet.png", sheet, png);
  }

  // Written last: its presence marks a finished dataset.
  write_bytes(out / kConfigFile, text);

  summary.people = P;
  summary.frames = c.frames;
  for (const auto& r : recs) summary.images += r.layout.num_cameras() * c.frames;
  summary.bytes = folder_bytes(out);
  summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return summary;
}

}  // namespace th::synth
