#include "tests/test_streams.h"

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
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

Status WritePan(const std::string& path, const EncoderOptions& options, int frames, double vx_px,
                double vy_px, int width_px, int height_px) {
  const int margin = static_cast<int>(std::ceil(frames * (std::abs(vx_px) + std::abs(vy_px)))) + 8;
  const cv::Mat tex = NoiseTexture(width_px + 2 * margin, height_px + 2 * margin, 7);
  auto enc = VideoEncoder::Open(path, width_px, height_px, options);
  if (!enc.ok()) return enc.status();
  cv::Mat frame;
  for (int i = 0; i < frames; ++i) {
    // Frame i shows texture point q at q - margin + i * v: sample at x + margin - i * v.
    const cv::Matx23d src_from_dst(1, 0, margin - i * vx_px, 0, 1, margin - i * vy_px);
    cv::warpAffine(tex, frame, src_from_dst, cv::Size(width_px, height_px),
                   cv::INTER_CUBIC | cv::WARP_INVERSE_MAP);
    SLAPSE_RETURN_IF_ERROR((*enc)->Write(frame));
  }
  return (*enc)->Finish();
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
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(sa);
  int port = 0;
  if (bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len) == 0) {
    port = ntohs(sa.sin_port);
  }
  close(fd);
  return port;
}

}  // namespace slapse::testing
