#include "tests/test_streams.h"

#include <atomic>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <opencv2/imgproc.hpp>

#include "core/common/intrinsics_io.h"
#include "core/mv/mpeg2_syntax.h"

namespace slapse::testing {

std::string MakeTempDir(const std::string& tag) {
  static std::atomic<int> counter{0};
  const auto dir =
      std::filesystem::temp_directory_path() /
      ("slapse_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

cv::Mat NoiseTexture(int width_px, int height_px, uint64_t seed) {
  std::mt19937_64 rng(seed);
  cv::Mat tex(height_px, width_px, CV_32FC3);
  for (int r = 0; r < height_px; ++r) {
    auto* row = tex.ptr<cv::Vec3f>(r);
    for (int c = 0; c < width_px; ++c) {
      for (int k = 0; k < 3; ++k) row[c][k] = static_cast<float>(rng() % 256);
    }
  }
  // Two scales of detail: fine grain that pins sub-pixel matches, coarse blobs
  // that keep the block matcher out of local minima.
  cv::Mat fine, coarse;
  cv::GaussianBlur(tex, fine, cv::Size(0, 0), 1.2);
  cv::GaussianBlur(tex, coarse, cv::Size(0, 0), 6.0);
  cv::Mat mix = 1.5 * (fine - 128.0) + 4.0 * (coarse - 128.0) + 128.0;
  cv::Mat out;
  mix.convertTo(out, CV_8UC3);
  return out;
}

namespace {

// Frame `i` of a pan over `tex` (WritePan): the point q of the texture sits at
// q - margin + t * v, t = i (+ 0.5 for the odd rows of an interlaced camera).
cv::Mat PanFrame(const cv::Mat& tex, int margin, int i, double vx_px, double vy_px, int width_px,
                 int height_px, bool interlaced) {
  auto render = [&](double t) {
    const cv::Matx23d src_from_dst(1, 0, margin - t * vx_px, 0, 1, margin - t * vy_px);
    cv::Mat frame;
    cv::warpAffine(tex, frame, src_from_dst, cv::Size(width_px, height_px),
                   cv::INTER_CUBIC | cv::WARP_INVERSE_MAP);
    return frame;
  };
  cv::Mat frame = render(i);
  if (interlaced) {
    const cv::Mat bottom = render(i + 0.5);
    for (int r = 1; r < height_px; r += 2) bottom.row(r).copyTo(frame.row(r));
  }
  return frame;
}

// Texture beyond the frame for the whole pan (half a frame more when interlaced).
int PanMargin(int frames, double vx_px, double vy_px, bool interlaced) {
  const double span = frames + (interlaced ? 0.5 : 0.0);
  return static_cast<int>(std::ceil(span * (std::abs(vx_px) + std::abs(vy_px)))) + 8;
}

// An elementary stream's start-code units (each from its 00 00 01 to the next).
std::vector<std::string> StartCodeUnits(const std::string& es) {
  std::vector<size_t> starts;
  for (size_t i = 0; i + 3 < es.size(); ++i) {
    if (es[i] == 0 && es[i + 1] == 0 && es[i + 2] == 1) starts.push_back(i);
  }
  std::vector<std::string> units;
  for (size_t k = 0; k < starts.size(); ++k) {
    const size_t end = k + 1 < starts.size() ? starts[k + 1] : es.size();
    units.push_back(es.substr(starts[k], end - starts[k]));
  }
  return units;
}

uint8_t UnitCode(const std::string& u) { return static_cast<uint8_t>(u[3]); }
int ExtensionId(const std::string& u) { return static_cast<uint8_t>(u[4]) >> 4; }
// A picture's own units after its header: its picture coding extension (id 8) and slices.
bool InPicture(const std::string& u) {
  const uint8_t c = UnitCode(u);
  return (c >= 0x01 && c <= 0xAF) || (c == 0xB5 && ExtensionId(u) == 8);
}

// The pictures of an elementary stream: header, coding extension, slices.
std::vector<std::string> Pictures(const std::vector<std::string>& units) {
  std::vector<std::string> pictures;
  for (const std::string& u : units) {
    if (UnitCode(u) == 0x00) {
      pictures.push_back(u);
    } else if (!pictures.empty() && InPicture(u)) {
      pictures.back() += u;
    }
  }
  return pictures;
}

// A field picture from a progressive picture's units: the coding extension's
// picture_structure (1 top, 2 bottom); top_field_first, frame_pred_frame_dct,
// chroma_420_type and progressive_frame 0 (a field picture's values).
std::string AsFieldPicture(std::string picture, int structure) {
  const size_t i = FindMpeg2PictureCodingExtension(reinterpret_cast<const uint8_t*>(picture.data()),
                                                   picture.size());
  if (i + 8 >= picture.size()) return picture;
  const size_t ps = i + kMpeg2PictureStructureByte;
  picture[ps] = static_cast<char>((picture[ps] & 0xFC) | structure);
  picture[i + 7] = static_cast<char>(picture[i + 7] & ~0xC1);
  picture[i + 8] = static_cast<char>(picture[i + 8] & ~0x80);
  return picture;
}

}  // namespace

Status WritePan(const std::string& path, const EncoderOptions& options, int frames, double vx_px,
                double vy_px, int width_px, int height_px) {
  const int margin = PanMargin(frames, vx_px, vy_px, options.interlaced);
  const cv::Mat tex = NoiseTexture(width_px + 2 * margin, height_px + 2 * margin, 7);
  auto enc = VideoEncoder::Open(path, width_px, height_px, options);
  if (!enc.ok()) return enc.status();
  for (int i = 0; i < frames; ++i) {
    SLAPSE_RETURN_IF_ERROR((*enc)->Write(
        PanFrame(tex, margin, i, vx_px, vy_px, width_px, height_px, options.interlaced)));
  }
  return (*enc)->Finish();
}

Status WriteMpeg2IntraFieldPictures(const std::string& path, int frames, double vx_px, double vy_px,
                                    int width_px, int height_px) {
  if (height_px % 32 != 0) return InvalidArgumentError("field pictures need a height of 32 n");
  const int margin = PanMargin(frames, vx_px, vy_px, true);
  const cv::Mat tex = NoiseTexture(width_px + 2 * margin, height_px + 2 * margin, 7);
  EncoderOptions intra;
  intra.b_frames = 0;
  intra.gop_size = 1;
  const std::string dir = MakeTempDir("fields");
  std::string es[2];
  for (int field = 0; field < 2; ++field) {
    const std::string field_path = dir + "/field" + std::to_string(field) + ".m2v";
    auto enc = VideoEncoder::Open(field_path, width_px, height_px / 2, intra);
    if (!enc.ok()) return enc.status();
    for (int i = 0; i < frames; ++i) {
      const cv::Mat frame = PanFrame(tex, margin, i, vx_px, vy_px, width_px, height_px, true);
      cv::Mat rows(height_px / 2, width_px, frame.type());
      for (int r = 0; r < height_px / 2; ++r) frame.row(2 * r + field).copyTo(rows.row(r));
      SLAPSE_RETURN_IF_ERROR((*enc)->Write(rows));
    }
    SLAPSE_RETURN_IF_ERROR((*enc)->Finish());
    es[field] = ReadFileBytes(field_path);
  }
  const std::vector<std::string> top = StartCodeUnits(es[0]);
  const std::vector<std::string> bottom = Pictures(StartCodeUnits(es[1]));
  std::string out;
  size_t next_bottom = 0;
  for (size_t i = 0; i < top.size(); ++i) {
    std::string u = top[i];
    if (UnitCode(u) == 0xB3) {  // sequence header: vertical_size (12 bits at byte 5.5)
      u[5] = static_cast<char>((u[5] & 0xF0) | ((height_px >> 8) & 0x0F));
      u[6] = static_cast<char>(height_px & 0xFF);
    } else if (UnitCode(u) == 0xB5 && ExtensionId(u) == 1) {
      u[5] = static_cast<char>(u[5] & ~0x08);  // progressive_sequence = 0
    } else if (UnitCode(u) == 0x00) {
      std::string picture = u;
      while (i + 1 < top.size() && InPicture(top[i + 1])) picture += top[++i];
      if (next_bottom >= bottom.size()) return InternalError("fewer bottom than top fields");
      out += AsFieldPicture(picture, kMpeg2TopField) +
             AsFieldPicture(bottom[next_bottom++], kMpeg2BottomField);
      continue;
    } else if (InPicture(u)) {
      continue;  // (not reached: a picture's units follow its header)
    }
    out += u;
  }
  WriteFileBytes(path, out);
  return Status::Ok();
}

SimulateOptions SmallMpeg2DriveOptions(uint64_t seed, double duration_s) {
  SimulateOptions sim;
  sim.seed = seed;
  sim.duration_s = duration_s;
  sim.width_px = 320;
  sim.height_px = 240;
  sim.supersampling = 1;
  sim.encoder.codec = VideoCodec::kMpeg2;
  return sim;
}

StatusOr<TestDrive> SimulateTestDrive(const std::string& tag, SimulateOptions options) {
  TestDrive drive;
  drive.dir = MakeTempDir(tag);
  options.output_dir = drive.dir;
  SLAPSE_RETURN_IF_ERROR(SimulateDrive(options, &drive.report));
  drive.video_path = drive.report.video_path;
  auto k = ReadIntrinsicsJson(drive.dir + "/intrinsics.json");
  if (!k.ok()) return k.status();
  drive.intrinsics = *k;
  return drive;
}

std::string ReadFileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void WriteFileBytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

int RunCommand(const std::string& cmd) {
  const int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

int ChildProcess::Wait(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (pid_ > 0) {
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    }
    if (std::chrono::steady_clock::now() > deadline) return -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return -1;
}

void ChildProcess::Freeze() {
  if (pid_ > 0) kill(pid_, SIGSTOP);
}

void ChildProcess::Kill() {
  if (pid_ <= 0) return;
  kill(pid_, SIGKILL);
  waitpid(pid_, nullptr, 0);
  pid_ = -1;
}

LoggedProcess::LoggedProcess(std::vector<std::string> argv, const std::string& log) {
  std::vector<char*> c;
  for (std::string& a : argv) c.push_back(a.data());
  c.push_back(nullptr);
  pid_ = fork();
  if (pid_ == 0) {
    const int out = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    dup2(out, 1);
    dup2(out, 2);
    execv(c[0], c.data());
    _exit(127);
  }
}

void LoggedProcess::Signal(int sig) {
  if (pid_ > 0) kill(pid_, sig);
}

int FreeLoopbackTcpPort() {
  // Never the same port twice in one test process: a test that takes
  // several (replicas, a proxy) needs them distinct, and a port released at
  // once may be handed out again. Below the kernel's ephemeral range
  // (ip_local_port_range, usually from 32768), so that no outgoing
  // connection of a test running beside this one (gRPC clients, ffmpeg) is
  // given the port between this check and the test's listen: a port taken
  // that way failed a replica's start ("cannot listen ... in use"). The
  // candidates start at a per-process random place, so parallel test
  // processes do not try the same ones.
  static std::mutex mutex;
  static std::set<int> handed_out;
  static std::mt19937 rng(static_cast<unsigned>(getpid()) * 2654435761u ^
                          static_cast<unsigned>(time(nullptr)));
  std::lock_guard<std::mutex> lock(mutex);
  int ephemeral_low = 32768;
  std::ifstream range("/proc/sys/net/ipv4/ip_local_port_range");
  if (!(range >> ephemeral_low)) ephemeral_low = 32768;
  constexpr int kLowest = 10000;
  if (ephemeral_low <= kLowest + 1000) ephemeral_low = 65536;  // odd range: take any above kLowest
  std::uniform_int_distribution<int> pick(kLowest, ephemeral_low - 1);
  for (int attempt = 0; attempt < 200; ++attempt) {
    const int candidate = pick(rng);
    if (handed_out.count(candidate) != 0) continue;
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    sa.sin_port = htons(static_cast<uint16_t>(candidate));
    const bool free = bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) == 0;
    close(fd);
    if (free) {
      handed_out.insert(candidate);
      return candidate;
    }
  }
  return 0;
}

}  // namespace slapse::testing
