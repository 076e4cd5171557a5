// Streams with known content, made at test time by the real encoders.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <string>

#include <opencv2/core.hpp>

#include "core/common/camera.h"
#include "core/common/status.h"
#include "lab/codec/video_encoder.h"
#include "lab/sim/simulate.h"

namespace slapse::testing {

// A fresh directory under the system temp dir, unique per call.
std::string MakeTempDir(const std::string& tag);

// A band-limited random texture (8-bit BGR), deterministic per seed.
cv::Mat NoiseTexture(int width_px, int height_px, uint64_t seed);

// Writes `frames` frames of a global pan: the content of frame i is the
// texture moved by i * (vx_px, vy_px), i.e. a point at p in frame i sits at
// p + (j - i) * v in frame j. The true MV of a block at c referring from frame
// j to frame r is therefore (r - j) * v. With options.interlaced the camera
// is interlaced: the odd rows (bottom field) of frame i show the pan at i + 0.5.
Status WritePan(const std::string& path, const EncoderOptions& options, int frames, double vx_px,
                double vy_px, int width_px = 320, int height_px = 240);

// An MPEG-2 elementary stream (.m2v) of `frames` intra-coded frames of a pan
// (as WritePan, interlaced) coded as field pictures: each frame a top field
// picture and a bottom field picture. No encoder in Debian 12 writes field
// pictures (mjpegtools' mpeg2enc crashes in its field mode), so the fields are
// encoded by libavcodec's mpeg2video as intra-only progressive pictures of
// half the height, and their pictures are spliced into one stream: intra
// macroblocks have the same syntax in a field picture as in a progressive
// frame picture; the sequence header gets the full height and
// progressive_sequence = 0, each picture coding extension its field.
Status WriteMpeg2IntraFieldPictures(const std::string& path, int frames, double vx_px, double vy_px,
                                    int width_px = 320, int height_px = 256);

// A simulated drive (lab/sim) on disk.
struct TestDrive {
  std::string dir;         // the simulator's output directory (ground truth, intrinsics.json)
  std::string video_path;  // the encoded drive
  Intrinsics intrinsics;   // its camera, as intrinsics.json holds it
  SimulateReport report;
};

// The small drives the service tests stream: 320x240 MPEG-2 IBBBP without
// supersampling (quick to render and to process), `duration_s` long.
SimulateOptions SmallMpeg2DriveOptions(uint64_t seed, double duration_s);

// Simulates a drive with `options` into a fresh temp dir tagged `tag` (the
// options' output_dir is replaced).
StatusOr<TestDrive> SimulateTestDrive(const std::string& tag, SimulateOptions options);

// Reads a whole file into memory.
std::string ReadFileBytes(const std::string& path);
void WriteFileBytes(const std::string& path, const std::string& bytes);

// Runs a shell command, returns its exit code.
int RunCommand(const std::string& cmd);

// A forked child process (a camera, an RTSP server) that a test owns: the
// subclass forks and sets pid_; Kill() and the destructor kill it (SIGKILL)
// and reap it, so no test path leaks a process.
class ChildProcess {
 public:
  ChildProcess() = default;
  ~ChildProcess() { Kill(); }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  bool started() const { return pid_ > 0; }
  // The exit code once it exits within `timeout`; -1 if it is still running
  // (or died by a signal).
  int Wait(std::chrono::milliseconds timeout);
  // Freezes the process (SIGSTOP): its connections stay open, nothing is sent.
  void Freeze();
  void Kill();

 protected:
  pid_t pid_ = -1;
};

// A child running argv[0] with `argv`, its stdout and stderr appended to
// `log` (e.g. `slapse serve` in a test).
class LoggedProcess : public ChildProcess {
 public:
  LoggedProcess(std::vector<std::string> argv, const std::string& log);
  void Signal(int sig);
};

// A TCP port on 127.0.0.1 that nothing listens on (bound, then released),
// never the same twice in one process: for a server the test starts, or a
// camera that is not there. 0 if none could be bound.
int FreeLoopbackTcpPort();

}  // namespace slapse::testing
