// The fault catalogue: bad inputs and faults, one after another, against one
// real server on 127.0.0.1 while a healthy camera (ffmpeg publishing over
// RTSP) streams to a session of its own. Each item asserts the exact status
// code (of the rpc, or of the session's ending) and a fragment of its
// message; at the end the healthy session must have FINISHED with its poses.
// The table printed at the end is the catalogue (input -> status -> message).
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include "client/lib/client.h"
#include "lab/sim/simulate.h"
#include "server/server.h"
#include "tests/server_fixture.h"
#include "tests/test_streams.h"

namespace slapse {
namespace {

using client::SlapseClient;
using testing::FfmpegProcess;

// What an item ended with: an rpc's error (state STATE_UNSPECIFIED), or the
// session's end (FAILED: its error; FINISHED / STOPPED: its state_message).
struct Outcome {
  v1::Session::State state = v1::Session::STATE_UNSPECIFIED;
  StatusCode code = StatusCode::kOk;
  std::string message;
};

struct Item {
  std::string input;
  v1::Session::State want_state;  // STATE_UNSPECIFIED: the rpc itself fails
  StatusCode want_code;
  std::string fragment;
  std::function<Outcome()> run;
};

Outcome FromStatus(const Status& s) {
  return {v1::Session::STATE_UNSPECIFIED, s.code(), s.message()};
}

// The CLI's exit code for `args` (stdout and stderr discarded).
int RunCli(const std::string& args) {
  return testing::RunCommand(std::string(SLAPSE_CLI) + " " + args + " >/dev/null 2>&1");
}

class FaultCatalogueTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto drive = testing::SimulateTestDrive("fault_catalogue_drive",
                                            testing::SmallMpeg2DriveOptions(5, 2.0));
    ASSERT_TRUE(drive.ok()) << drive.status().ToString();
    dir_ = testing::MakeTempDir("fault_catalogue");
    drive_path_ = drive->video_path;
    drive_ = testing::ReadFileBytes(drive_path_);
    k_ = drive->intrinsics;
    server::ServerOptions o;
    o.address = "127.0.0.1";
    o.port = 0;
    o.sessions.max_sessions = 4;
    o.sessions.upload_buffer_bytes = 256 << 10;
    o.sessions.max_upload_bytes = static_cast<int64_t>(drive_.size()) + 4096;
    o.sessions.create_idle_timeout_ms = 1000;
    o.sessions.upload_stall_timeout_ms = 1000;
    o.shutdown_grace_s = 1;
    auto server = server::SlapseServer::Start(o);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    target_ = "127.0.0.1:" + std::to_string(server_->port());
    client_ = SlapseClient::Connect(target_, testing::TestClientOptions());
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  v1::Session Request() const {
    v1::Session s;
    s.mutable_upload();
    v1::Intrinsics* k = s.mutable_intrinsics();
    k->set_fx_px(k_.fx_px);
    k->set_fy_px(k_.fy_px);
    k->set_cx_px(k_.cx_px);
    k->set_cy_px(k_.cy_px);
    return s;
  }

  // Waits for `name` to end and reads how.
  Outcome EndOf(const std::string& name) {
    v1::SessionEvent last;
    Status watched = client_->Watch(name, 0, [&](const v1::SessionEvent& e) {
      last = e;
      return true;
    });
    if (!watched.ok()) return FromStatus(watched);
    auto got = client_->GetSession(name);
    if (!got.ok()) return FromStatus(got.status());
    // Every ending is a state change in the event log, with the same message.
    EXPECT_EQ(last.state_change().state(), got->state()) << name;
    EXPECT_EQ(last.state_change().message(), got->state_message()) << name;
    if (got->state() == v1::Session::FAILED) {
      return {got->state(), static_cast<StatusCode>(got->error().code()), got->error().message()};
    }
    return {got->state(), StatusCode::kOk, got->state_message()};
  }

  // Polls until `name` has left CREATED (at most 10 s).
  void WaitWhileCreated(const std::string& name) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < deadline) {
      auto got = client_->GetSession(name);
      if (!got.ok() || got->state() != v1::Session::CREATED) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }

  // Creates `request`, then runs `feed` on the session (may be empty) and
  // waits for its end.
  Outcome CreateAndEnd(const v1::Session& request,
                       const std::function<void(const std::string&)>& feed = nullptr) {
    auto created = client_->CreateSession(request);
    if (!created.ok()) return FromStatus(created.status());
    if (feed) feed(created->name());
    return EndOf(created->name());
  }

  Outcome Upload(const v1::Session& request, const std::string& bytes) {
    return CreateAndEnd(request,
                        [&](const std::string& name) { (void)client_->UploadBytes(name, bytes); });
  }

  // An UploadStream held open by the test: `first` bytes, then `then` runs
  // with the live stream's context (cancel it, or wait).
  Outcome RawUpload(const std::string& first,
                    const std::function<void(const std::string&, grpc::ClientContext*)>& then) {
    auto created = client_->CreateSession(Request());
    if (!created.ok()) return FromStatus(created.status());
    auto stub = v1::SlapseService::NewStub(
        grpc::CreateChannel(target_, grpc::InsecureChannelCredentials()));
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    v1::Session response;
    auto writer = stub->UploadStream(&ctx, &response);
    for (size_t at = 0; at < first.size() || at == 0; at += 32 << 10) {
      v1::UploadChunk chunk;
      if (at == 0) chunk.set_name(created->name());
      chunk.set_data(first.substr(at, 32 << 10));
      if (!writer->Write(chunk)) break;
    }
    then(created->name(), &ctx);
    (void)writer->Finish();
    return EndOf(created->name());
  }

  std::vector<Item> Catalogue();
  void AddStreamItems(std::vector<Item>* items);
  void AddUploadItems(std::vector<Item>* items);
  void AddStateItems(std::vector<Item>* items);
  void AddSecurityItems(std::vector<Item>* items);

  std::string dir_, drive_path_, drive_, target_;
  Intrinsics k_;
  std::unique_ptr<server::SlapseServer> server_;
  std::unique_ptr<SlapseClient> client_;
};

// Adds an item whose request is the valid one edited by `edit`.
using AddFn = std::function<void(const std::string& input, const std::string& fragment,
                                 std::function<void(v1::Session*)> edit)>;

void AddIntrinsicsItems(const AddFn& add) {
  add("intrinsics cx = 1e9 (width/height given)", "principal point (cx_px 1e+09",
      [](v1::Session* r) {
        r->mutable_intrinsics()->set_cx_px(1e9);
        r->mutable_intrinsics()->set_width_px(640);
        r->mutable_intrinsics()->set_height_px(480);
      });
  add("intrinsics fx = 1e-300 (width/height given)",
      "fx_px 1e-300 gives a horizontal field of view of 180 deg", [](v1::Session* r) {
        r->mutable_intrinsics()->set_fx_px(1e-300);
        r->mutable_intrinsics()->set_cx_px(320);
        r->mutable_intrinsics()->set_cy_px(240);
        r->mutable_intrinsics()->set_width_px(640);
        r->mutable_intrinsics()->set_height_px(480);
      });
  add("intrinsics fx = 1e6 on 640x480 (FOV 0.04 deg)", "want 10 to 170 deg", [](v1::Session* r) {
    r->mutable_intrinsics()->set_fx_px(1e6);
    r->mutable_intrinsics()->set_cx_px(320);
    r->mutable_intrinsics()->set_cy_px(240);
    r->mutable_intrinsics()->set_width_px(640);
    r->mutable_intrinsics()->set_height_px(480);
  });
  add("intrinsics fx = -1", "fx_px and fy_px must be finite and > 0",
      [](v1::Session* r) { r->mutable_intrinsics()->set_fx_px(-1); });
  add("intrinsics fy = NaN", "fx_px and fy_px must be finite and > 0",
      [](v1::Session* r) { r->mutable_intrinsics()->set_fy_px(std::nan("")); });
  add("intrinsics cx = inf", "cx_px and cy_px must be finite",
      [](v1::Session* r) { r->mutable_intrinsics()->set_cx_px(INFINITY); });
  add("intrinsics width_px = -1", "width_px and height_px must be >= 0",
      [](v1::Session* r) { r->mutable_intrinsics()->set_width_px(-1); });
  add("no intrinsics", "session.intrinsics is required",
      [](v1::Session* r) { r->clear_intrinsics(); });
}

void AddOptionsItems(const AddFn& add) {
  add("pipeline_options.scale_source = 99", "scale_source 99 is not one of UP_TO_SCALE (0)",
      [](v1::Session* r) {
        r->mutable_pipeline_options()->set_scale_source(
            static_cast<v1::PipelineOptions::ScaleSource>(99));
      });
  add("no source", "session.source is required", [](v1::Session* r) { r->clear_upload(); });
  add("eps_h_px = 1000", "pipeline_options.eps_h_px must be in [0, 100]",
      [](v1::Session* r) { r->mutable_pipeline_options()->set_eps_h_px(1000); });
  add("FIRST_STEP without first_step_m", "first_step_m must be > 0", [](v1::Session* r) {
    r->mutable_pipeline_options()->set_scale_source(v1::PipelineOptions::FIRST_STEP);
  });
  add("SPEED without speed_mps", "speed_mps must be > 0", [](v1::Session* r) {
    r->mutable_pipeline_options()->set_scale_source(v1::PipelineOptions::SPEED);
  });
  add("CAMERA_HEIGHT with camera_height_m = -2", "camera_height_m must be > 0", [](v1::Session* r) {
    r->mutable_pipeline_options()->set_scale_source(v1::PipelineOptions::CAMERA_HEIGHT);
    r->mutable_pipeline_options()->set_camera_height_m(-2);
  });
}

void AddSourceItems(const AddFn& add) {
  add("rtp_sdp.sdp empty", "rtp_sdp.sdp: required",
      [](v1::Session* r) { r->mutable_rtp_sdp()->set_sdp(""); });
  add("rtp_sdp.sdp 'hello'", "is not '<letter>=<value>'",
      [](v1::Session* r) { r->mutable_rtp_sdp()->set_sdp("hello"); });
  add("rtp_sdp.sdp audio only", "no video media line", [](v1::Session* r) {
    r->mutable_rtp_sdp()->set_sdp("v=0\nc=IN IP4 127.0.0.1\nm=audio 5004 RTP/AVP 0\n");
  });
  add("rtp_sdp.sdp without c=", "no connection line",
      [](v1::Session* r) { r->mutable_rtp_sdp()->set_sdp("v=0\nm=video 5004 RTP/AVP 32\n"); });
  add("rtp_sdp.sdp m=video x", "m=video line without a port", [](v1::Session* r) {
    r->mutable_rtp_sdp()->set_sdp("v=0\nc=IN IP4 127.0.0.1\nm=video x RTP/AVP 32\n");
  });
  add("rtp_sdp receive_timeout_ms = -1", "must be >= 0 (0 = the default)", [](v1::Session* r) {
    r->mutable_rtp_sdp()->set_sdp(testing::Mpeg2RtpSdp(5004));
    r->mutable_rtp_sdp()->set_receive_timeout_ms(-1);
  });
  add("rtsp_push.path '/cam'", "is not a path",
      [](v1::Session* r) { r->mutable_rtsp_push()->set_path("/cam"); });
  add("rtsp_push.path 'a b'", "is not a path",
      [](v1::Session* r) { r->mutable_rtsp_push()->set_path("a b"); });
  add("rtsp_pull.url empty", "rtsp_pull.url is required",
      [](v1::Session* r) { r->mutable_rtsp_pull()->set_url(""); });
  add("rtsp_pull.url http://cam/1", "does not start with rtsp://",
      [](v1::Session* r) { r->mutable_rtsp_pull()->set_url("http://cam/1"); });
  add("rtsp_pull.url port 70000", "has a port that is not 1..65535",
      [](v1::Session* r) { r->mutable_rtsp_pull()->set_url("rtsp://cam:70000/1"); });
  add("rtsp_pull.url with password, bad host", "rtsp://***@",
      [](v1::Session* r) { r->mutable_rtsp_pull()->set_url("rtsp://admin:secret@c%m/1"); });
  add("reconnect backoff 0.5", "backoff_multiplier must be in [1, 100]", [](v1::Session* r) {
    r->mutable_rtsp_pull()->set_url("rtsp://cam/1");
    r->mutable_rtsp_pull()->mutable_reconnect()->set_backoff_multiplier(0.5);
  });
  add("reconnect max < initial interval", "must be >= initial_interval_ms", [](v1::Session* r) {
    r->mutable_rtsp_pull()->set_url("rtsp://cam/1");
    r->mutable_rtsp_pull()->mutable_reconnect()->set_initial_interval_ms(5000);
    r->mutable_rtsp_pull()->mutable_reconnect()->set_max_interval_ms(1000);
  });
}

// The items that CreateSession / ListSessions refuse (INVALID_ARGUMENT).
void AddRequestItems(const v1::Session& ok, SlapseClient* c, std::vector<Item>* items) {
  const auto I = v1::Session::STATE_UNSPECIFIED;
  const auto bad = StatusCode::kInvalidArgument;
  const AddFn add = [&](const std::string& input, const std::string& fragment,
                        std::function<void(v1::Session*)> edit) {
    items->push_back({input, I, bad, fragment, [c, ok, edit] {
                        v1::Session r = ok;
                        edit(&r);
                        return FromStatus(c->CreateSession(r).status());
                      }});
  };
  AddIntrinsicsItems(add);
  AddOptionsItems(add);
  AddSourceItems(add);
  auto list = [c](int page_size, const std::string& token, int state) {
    return [=] {
      return FromStatus(
          c->ListSessions(page_size, token, static_cast<v1::Session::State>(state)).status());
    };
  };
  items->push_back({"ListSessions state_filter = 42", I, bad,
                    "state_filter 42 is not one of STATE_UNSPECIFIED (0), CREATED (1)",
                    list(0, "", 42)});
  items->push_back(
      {"ListSessions page_size = -1", I, bad, "page_size must be >= 0", list(-1, "", 0)});
  items->push_back({"ListSessions page_token 'x'", I, bad,
                    "page_token is not one this server issued", list(0, "x", 0)});
}

// Names that are malformed or unknown, on every rpc that takes one.
void AddNameItems(SlapseClient* c, std::vector<Item>* items) {
  const auto I = v1::Session::STATE_UNSPECIFIED;
  items->push_back({"GetSession 'nonsense'", I, StatusCode::kInvalidArgument,
                    "is not a session name",
                    [c] { return FromStatus(c->GetSession("nonsense").status()); }});
  items->push_back({"GetSession unknown", I, StatusCode::kNotFound, "no session 'sessions/999999'",
                    [c] { return FromStatus(c->GetSession("sessions/999999").status()); }});
  items->push_back({"StopSession unknown", I, StatusCode::kNotFound, "no session",
                    [c] { return FromStatus(c->StopSession("sessions/999999").status()); }});
  items->push_back({"DeleteSession unknown", I, StatusCode::kNotFound, "no session",
                    [c] { return FromStatus(c->DeleteSession("sessions/999999")); }});
  items->push_back({"GetTrajectory unknown", I, StatusCode::kNotFound, "no session",
                    [c] { return FromStatus(c->GetTrajectory("sessions/999999").status()); }});
  items->push_back({"UploadStream to unknown", I, StatusCode::kNotFound, "no session",
                    [c] { return FromStatus(c->UploadBytes("sessions/999999", "abc").status()); }});
  // Paging of the snapshots (checked before the name).
  auto trajectory_page = [c](int page_size, const std::string& token, double start_s,
                             double end_s) {
    return [=] {
      v1::GetTrajectoryRequest r;
      r.set_name("sessions/999999");
      r.set_page_size(page_size);
      r.set_page_token(token);
      r.set_start_time_s(start_s);
      r.set_end_time_s(end_s);
      return FromStatus(c->GetTrajectoryPage(r).status());
    };
  };
  items->push_back({"GetTrajectory page_size = -1", I, StatusCode::kInvalidArgument,
                    "page_size must be >= 0", trajectory_page(-1, "", 0, 0)});
  items->push_back({"GetTrajectory page_token 'x'", I, StatusCode::kInvalidArgument,
                    "bad page_token 'x'", trajectory_page(10, "x", 0, 0)});
  items->push_back({"GetTrajectory time range [5 s, 1 s)", I, StatusCode::kInvalidArgument,
                    "the time range [start_time_s, end_time_s) must be finite and non-empty",
                    trajectory_page(10, "", 5, 1)});
  items->push_back(
      {"GetPlaneMap page_token '-3'", I, StatusCode::kInvalidArgument, "bad page_token '-3'", [c] {
         v1::GetPlaneMapRequest r;
         r.set_name("sessions/999999");
         r.set_page_token("-3");
         return FromStatus(c->GetPlaneMapPage(r).status());
       }});
  items->push_back({"WatchSession unknown", I, StatusCode::kNotFound, "no session", [c] {
                      return FromStatus(c->Watch("sessions/999999", 0,
                                                 [](const v1::SessionEvent&) { return true; }));
                    }});
}

// A UDP socket bound to a free even port of 127.0.0.1 (held until closed).
int BindUdp(int* port) {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  sa.sin_port = htons(static_cast<uint16_t>(testing::FreeRtpPort()));
  socklen_t len = sizeof(sa);
  bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa));
  getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
  *port = ntohs(sa.sin_port);
  return fd;
}

std::vector<Item> FaultCatalogueTest::Catalogue() {
  std::vector<Item> items;
  AddRequestItems(Request(), client_.get(), &items);
  AddNameItems(client_.get(), &items);
  const auto I = v1::Session::STATE_UNSPECIFIED;

  items.push_back({"RTP SDP whose port is in use", I, StatusCode::kFailedPrecondition,
                   "cannot be bound on this server: Address already in use", [this] {
                     int port = 0;
                     const int fd = BindUdp(&port);
                     v1::Session r = Request();
                     r.mutable_rtp_sdp()->set_sdp(testing::Mpeg2RtpSdp(port));
                     Outcome o = FromStatus(client_->CreateSession(r).status());
                     close(fd);
                     return o;
                   }});
  AddStreamItems(&items);
  AddUploadItems(&items);
  AddStateItems(&items);
  AddSecurityItems(&items);
  return items;
}

// Sessions that fail on what their stream shows.
void FaultCatalogueTest::AddStreamItems(std::vector<Item>* out) {
  std::vector<Item>& items = *out;
  const auto FAILED = v1::Session::FAILED;
  items.push_back({"cx = 1e9, size from the stream", FAILED, StatusCode::kInvalidArgument,
                   "principal point (cx_px 1e+09", [this] {
                     v1::Session r = Request();
                     r.mutable_intrinsics()->set_cx_px(1e9);
                     return Upload(r, drive_);
                   }});
  items.push_back({"fx = 1e-300, size from the stream", FAILED, StatusCode::kInvalidArgument,
                   "fx_px 1e-300 gives a horizontal field of view of 180 deg", [this] {
                     v1::Session r = Request();
                     r.mutable_intrinsics()->set_fx_px(1e-300);
                     return Upload(r, drive_);
                   }});
  items.push_back({"intrinsics for 1920x1080, stream smaller", FAILED, StatusCode::kInvalidArgument,
                   "intrinsics are for 1920x1080 but the stream is", [this] {
                     v1::Session r = Request();
                     r.mutable_intrinsics()->set_fx_px(1000);
                     r.mutable_intrinsics()->set_fy_px(1000);
                     r.mutable_intrinsics()->set_cx_px(960);
                     r.mutable_intrinsics()->set_cy_px(540);
                     r.mutable_intrinsics()->set_width_px(1920);
                     r.mutable_intrinsics()->set_height_px(1080);
                     return Upload(r, drive_);
                   }});
}

// Uploads that never start, stall, break off, are damaged or too large.
void FaultCatalogueTest::AddUploadItems(std::vector<Item>* out) {
  std::vector<Item>& items = *out;
  const auto FAILED = v1::Session::FAILED;
  items.push_back({"upload session never uploaded (create idle 1 s)", FAILED,
                   StatusCode::kDeadlineExceeded, "no upload began within 1 s",
                   [this] { return CreateAndEnd(Request()); }});
  items.push_back({"upload stalls after 64 KiB (stall 1 s)", FAILED, StatusCode::kDeadlineExceeded,
                   "the upload stalled: no bytes arrived for 1 s", [this] {
                     return RawUpload(drive_.substr(0, 64 << 10),
                                      [this](const std::string& name, grpc::ClientContext* ctx) {
                                        EndOf(name);
                                        ctx->TryCancel();
                                      });
                   }});
  items.push_back({"uploader disconnects mid-stream", FAILED, StatusCode::kCancelled,
                   "the upload ended before the client finished it", [this] {
                     return RawUpload(drive_.substr(0, drive_.size() / 2),
                                      [this](const std::string& name, grpc::ClientContext* ctx) {
                                        // Once the server has the upload (RUNNING), the client goes
                                        // away.
                                        WaitWhileCreated(name);
                                        ctx->TryCancel();
                                      });
                   }});
  items.push_back({"damaged stream (middle third overwritten)", FAILED, StatusCode::kDataLoss,
                   "stream damaged", [this] {
                     std::string bytes = drive_;
                     for (size_t i = bytes.size() / 3; i < 2 * bytes.size() / 3; ++i) {
                       bytes[i] = static_cast<char>(i * 131 % 251);
                     }
                     return Upload(Request(), bytes);
                   }});
  items.push_back({"upload larger than serve --max-upload-mb", FAILED,
                   StatusCode::kResourceExhausted, "exceeds the server's limit",
                   [this] { return Upload(Request(), drive_ + drive_); }});
  items.push_back({"not a video (text)", FAILED, StatusCode::kInvalidArgument,
                   "Invalid data found when processing input",
                   [this] { return Upload(Request(), std::string(200000, 'x')); }});
  items.push_back(
      {"static scene (no motion)", v1::Session::FINISHED, StatusCode::kOk, "no poses: ", [this] {
         const std::string still = dir_ + "/still.ts";
         testing::RunCommand(
             "ffmpeg -nostdin -loglevel error -y -f lavfi -i color=gray:size=320x240:"
             "rate=25 -frames:v 50 -c:v mpeg2video -g 12 -bf 2 " +
             still);
         v1::Session r = Request();
         r.mutable_intrinsics()->set_fx_px(300);
         r.mutable_intrinsics()->set_fy_px(300);
         r.mutable_intrinsics()->set_cx_px(160);
         r.mutable_intrinsics()->set_cy_px(120);
         return Upload(r, testing::ReadFileBytes(still));
       }});
}

// Timeouts of network sources, rpcs refused for the session's state, the
// CLI's exit codes and capacity.
void FaultCatalogueTest::AddStateItems(std::vector<Item>* out) {
  std::vector<Item>& items = *out;
  const auto FAILED = v1::Session::FAILED;
  const auto I = v1::Session::STATE_UNSPECIFIED;
  items.push_back(
      {"RTP with sized intrinsics (320x240 given): waits for its sender, not 'stream is 0x0'",
       v1::Session::FINISHED, StatusCode::kOk, "receive_timeout_ms=1000", [this] {
         const int port = testing::FreeRtpPort();
         v1::Session r = Request();
         r.mutable_intrinsics()->set_width_px(320);
         r.mutable_intrinsics()->set_height_px(240);
         r.mutable_rtp_sdp()->set_sdp(testing::Mpeg2RtpSdp(port));
         r.mutable_rtp_sdp()->set_start_timeout_ms(10000);
         r.mutable_rtp_sdp()->set_receive_timeout_ms(1000);
         Outcome o = CreateAndEnd(r, [&](const std::string&) {
           // The receiver first (README): send once the port is bound.
           if (!testing::WaitForLocalPort("udp", port, std::chrono::seconds(5))) return;
           FfmpegProcess sender({"-re", "-i", drive_path_, "-c", "copy", "-f", "rtp",
                                 "rtp://127.0.0.1:" + std::to_string(port)});
           sender.Wait(std::chrono::seconds(15));
         });
         // It must have made poses.
         if (o.message.find("no poses") != std::string::npos) o.code = StatusCode::kUnknown;
         return o;
       }});
  items.push_back({"RTSP push without publisher (start 300 ms)", FAILED,
                   StatusCode::kDeadlineExceeded,
                   "no RTSP publisher sent video within start_timeout_ms=300", [this] {
                     v1::Session r = Request();
                     r.mutable_rtsp_push()->set_path("nobody");
                     r.mutable_rtsp_push()->set_start_timeout_ms(300);
                     return CreateAndEnd(r);
                   }});
  items.push_back({"RTSP publisher killed mid-stream (no TEARDOWN)", FAILED,
                   StatusCode::kUnavailable, "lost without a TEARDOWN", [this] {
                     v1::Session r = Request();
                     r.mutable_rtsp_push()->set_path("killed");
                     r.mutable_rtsp_push()->set_start_timeout_ms(10000);
                     auto created = client_->CreateSession(r);
                     if (!created.ok()) return FromStatus(created.status());
                     FfmpegProcess cam({"-re", "-i", drive_path_, "-c", "copy", "-f", "rtsp",
                                        "-rtsp_transport", "tcp", testing::PublishUrl(*created)});
                     const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
                     while (std::chrono::steady_clock::now() < until) {
                       auto got = client_->GetSession(created->name());
                       if (!got.ok() || got->stats().frames() >= 5) break;
                       std::this_thread::sleep_for(std::chrono::milliseconds(20));
                     }
                     cam.Kill();  // SIGKILL: the connection closes without TEARDOWN
                     return EndOf(created->name());
                   }});
  items.push_back({"RTSP publisher with a wrong password (refused), then the right one",
                   v1::Session::FINISHED, StatusCode::kOk,
                   "the publisher ended the stream (TEARDOWN)", [this] {
                     v1::Session r = Request();
                     r.mutable_rtsp_push()->set_path("wrongpw");
                     r.mutable_rtsp_push()->set_start_timeout_ms(10000);
                     auto created = client_->CreateSession(r);
                     if (!created.ok()) return FromStatus(created.status());
                     v1::Session wrong = *created;
                     wrong.mutable_publish_credentials()->set_password("not-the-password");
                     FfmpegProcess bad({"-i", drive_path_, "-c", "copy", "-f", "rtsp",
                                        "-rtsp_transport", "tcp", testing::PublishUrl(wrong)});
                     if (bad.Wait(std::chrono::seconds(10)) == 0) {
                       (void)client_->StopSession(created->name());
                       return Outcome{v1::Session::STATE_UNSPECIFIED, StatusCode::kUnknown,
                                      "the wrong password was accepted"};
                     }
                     FfmpegProcess cam({"-re", "-i", drive_path_, "-c", "copy", "-f", "rtsp",
                                        "-rtsp_transport", "tcp", testing::PublishUrl(*created)});
                     cam.Wait(std::chrono::seconds(15));
                     return EndOf(created->name());
                   }});
  items.push_back(
      {"RTSP ANNOUNCE to an unknown path", I, StatusCode::kNotFound, "RTSP 404", [this] {
         const int status = testing::RtspRequestStatus(
             server_->sessions().rtsp_port(), "ANNOUNCE",
             "rtsp://127.0.0.1:" + std::to_string(server_->sessions().rtsp_port()) +
                 "/sessions/nosuchsession/cam",
             "v=0\r\nm=video 0 RTP/AVP 32\r\n");
         return Outcome{I, status == 404 ? StatusCode::kNotFound : StatusCode::kUnknown,
                        "RTSP " + std::to_string(status)};
       }});
  items.push_back({"RTP without sender (start 300 ms)", FAILED, StatusCode::kDeadlineExceeded,
                   "no RTP video arrived within start_timeout_ms=300", [this] {
                     v1::Session r = Request();
                     r.mutable_rtp_sdp()->set_sdp(testing::Mpeg2RtpSdp(testing::FreeRtpPort()));
                     r.mutable_rtp_sdp()->set_start_timeout_ms(300);
                     return CreateAndEnd(r);
                   }});
  items.push_back({"UploadStream to an RTSP push session", I, StatusCode::kFailedPrecondition,
                   "is not an upload session", [this] {
                     v1::Session r = Request();
                     r.mutable_rtsp_push()->set_path("notupload");
                     auto created = client_->CreateSession(r);
                     Outcome o = FromStatus(client_->UploadBytes(created->name(), "abc").status());
                     (void)client_->StopSession(created->name());
                     return o;
                   }});
  items.push_back(
      {"UploadStream to a FAILED session", I, StatusCode::kFailedPrecondition, "is FAILED", [this] {
         auto created = client_->CreateSession(Request());
         EndOf(created->name());  // the create-idle timeout fails it
         return FromStatus(client_->UploadBytes(created->name(), drive_).status());
       }});
  items.push_back(
      {"`slapse watch` of a FAILED session: exit 3", I, StatusCode::kOk, "exit 3", [this] {
         auto created = client_->CreateSession(Request());
         EndOf(created->name());
         const int rc = RunCli("watch " + created->name() + " --server " + target_);
         return Outcome{I, rc == 3 ? StatusCode::kOk : StatusCode::kUnknown,
                        "exit " + std::to_string(rc)};
       }});
  items.push_back(
      {"`slapse upload` to a session that fails: exit 3", I, StatusCode::kOk, "exit 3", [this] {
         v1::Session r = Request();
         r.mutable_intrinsics()->set_cx_px(1e9);
         auto created = client_->CreateSession(r);
         const int rc =
             RunCli("upload " + created->name() + " " + drive_path_ + " --server " + target_);
         EndOf(created->name());
         return Outcome{I, rc == 3 ? StatusCode::kOk : StatusCode::kUnknown,
                        "exit " + std::to_string(rc)};
       }});
  items.push_back({"more sessions than --max-sessions", I, StatusCode::kResourceExhausted,
                   "the server is at capacity", [this] {
                     std::vector<std::string> held;
                     Status s;
                     for (int i = 0; i < 8 && s.ok(); ++i) {
                       v1::Session r = Request();
                       r.mutable_rtsp_push()->set_path("hold" + std::to_string(i));
                       auto created = client_->CreateSession(r);
                       if (created.ok()) held.push_back(created->name());
                       s = created.status();
                     }
                     for (const std::string& name : held) (void)client_->StopSession(name);
                     return FromStatus(s);
                   }});
}

// Auth and secrets (server/auth.h): servers refused at start, and rpcs to a
// second server with bearer tokens (tenants "acme" and "globex").
void FaultCatalogueTest::AddSecurityItems(std::vector<Item>* out) {
  std::vector<Item>& items = *out;
  const auto I = v1::Session::STATE_UNSPECIFIED;
  const auto FAILED = v1::Session::FAILED;
  auto start = [](server::ServerOptions o) {
    o.port = 0;
    auto s = server::SlapseServer::Start(o);
    return FromStatus(s.status());
  };
  items.push_back({"serve on 0.0.0.0 without TLS and tokens", I, StatusCode::kFailedPrecondition,
                   "refusing to listen on 0.0.0.0 without TLS and bearer tokens", [start] {
                     server::ServerOptions o;
                     o.address = "0.0.0.0";
                     return start(o);
                   }});
  items.push_back({"serve with --tls-key but no --tls-cert", I, StatusCode::kInvalidArgument,
                   "TLS needs both a certificate and its key", [start] {
                     server::ServerOptions o;
                     o.auth.tls_key_file = "/nonexistent.key";
                     return start(o);
                   }});
  const std::string tokens = dir_ + "/tokens.json";
  items.push_back({"tokens file with a 5-character token", I, StatusCode::kInvalidArgument,
                   "tokens[0]: 'token' must be a string of at least 16 characters",
                   [start, tokens] {
                     testing::WriteFileBytes(
                         tokens, "{\"tokens\": [{\"token\": \"short\", \"tenant\": \"a\"}]}");
                     server::ServerOptions o;
                     o.auth.tokens_file = tokens;
                     return start(o);
                   }});
  // The server with tokens, shared by the items below (started by the first).
  auto secure = std::make_shared<std::unique_ptr<server::SlapseServer>>();
  auto client_with = [secure, tokens](const std::string& token) {
    if (*secure == nullptr) {
      testing::WriteFileBytes(tokens,
                              "{\"tokens\": [{\"token\": \"acme-token-0123456789\", \"tenant\": "
                              "\"acme\"}, {\"token\": \"globex-token-0123456789\", \"tenant\": "
                              "\"globex\"}, {\"token\": \"acme-reader-0123456789\", \"tenant\": "
                              "\"acme\", \"role\": \"read_only\"}]}");
      server::ServerOptions o;
      o.port = 0;
      o.auth.tokens_file = tokens;
      o.shutdown_grace_s = 1;
      auto s = server::SlapseServer::Start(o);
      EXPECT_TRUE(s.ok()) << s.status().ToString();
      if (s.ok()) *secure = std::move(*s);
    }
    client::ClientOptions c = testing::TestClientOptions();
    c.token = token;
    const int port = *secure ? (*secure)->port() : 1;
    return SlapseClient::Connect("127.0.0.1:" + std::to_string(port), c);
  };
  items.push_back({"rpc without a bearer token (tokens server)", I, server::kUnauthenticated,
                   "this server requires a bearer token", [client_with] {
                     return FromStatus(client_with("")->GetSession("sessions/1").status());
                   }});
  items.push_back({"rpc with an unknown bearer token", I, server::kUnauthenticated,
                   "the bearer token is not valid", [client_with] {
                     return FromStatus(
                         client_with("unknown-token-0123456789")->ListSessions(0, "", I).status());
                   }});
  items.push_back(
      {"GetSession of another tenant's session", I, StatusCode::kNotFound, "no session 'sessions/",
       [this, client_with] {
         auto created = client_with("acme-token-0123456789")->CreateSession(Request());
         if (!created.ok()) return FromStatus(created.status());
         Outcome o = FromStatus(
             client_with("globex-token-0123456789")->GetSession(created->name()).status());
         (void)client_with("acme-token-0123456789")->StopSession(created->name());
         return o;
       }});
  items.push_back({"CreateSession with a read-only token", I, StatusCode::kPermissionDenied,
                   "has a read-only token: CreateSession is not allowed", [this, client_with] {
                     return FromStatus(
                         client_with("acme-reader-0123456789")->CreateSession(Request()).status());
                   }});
  // RTP sender allow-list: ffmpeg sends from 127.0.0.1.
  auto rtp_from_ffmpeg = [this](const std::string& allowed) {
    const int port = testing::FreeRtpPort();
    v1::Session r = Request();
    r.mutable_rtp_sdp()->set_sdp(testing::Mpeg2RtpSdp(port));
    r.mutable_rtp_sdp()->add_allowed_senders(allowed);
    r.mutable_rtp_sdp()->set_start_timeout_ms(3000);
    r.mutable_rtp_sdp()->set_receive_timeout_ms(1000);
    return CreateAndEnd(r, [&](const std::string&) {
      if (!testing::WaitForLocalPort("udp", port, std::chrono::seconds(5))) return;
      FfmpegProcess sender({"-re", "-i", drive_path_, "-c", "copy", "-f", "rtp",
                            "rtp://127.0.0.1:" + std::to_string(port)});
      sender.Wait(std::chrono::seconds(15));
    });
  };
  items.push_back({"RTP from a sender not on allowed_senders (only 10.9.9.9)", FAILED,
                   StatusCode::kDeadlineExceeded,
                   "no RTP video arrived within start_timeout_ms=3000",
                   [rtp_from_ffmpeg] { return rtp_from_ffmpeg("10.9.9.9"); }});
  items.push_back({"RTP from an allowed sender (127.0.0.1)", v1::Session::FINISHED, StatusCode::kOk,
                   "receive_timeout_ms=1000", [rtp_from_ffmpeg] {
                     Outcome o = rtp_from_ffmpeg("127.0.0.1");
                     if (o.message.find("no poses") != std::string::npos)
                       o.code = StatusCode::kUnknown;
                     return o;
                   }});
  items.push_back({"RTP allowed_senders 'camera.local' (a name)", I, StatusCode::kInvalidArgument,
                   "allowed_senders[0] 'camera.local' is not an IPv4 or IPv6 address", [this] {
                     v1::Session r = Request();
                     r.mutable_rtp_sdp()->set_sdp(testing::Mpeg2RtpSdp(testing::FreeRtpPort()));
                     r.mutable_rtp_sdp()->add_allowed_senders("camera.local");
                     return FromStatus(client_->CreateSession(r).status());
                   }});
  items.push_back({"RTSP pull URL with password and ?token= (GetSession shows it masked)", I,
                   StatusCode::kOk, "rtsp://***@127.0.0.1:9/cam?token=***", [this] {
                     v1::Session r = Request();
                     r.clear_upload();
                     r.mutable_rtsp_pull()->set_url("rtsp://admin:pw1@127.0.0.1:9/cam?token=t0k");
                     r.mutable_rtsp_pull()->mutable_reconnect()->set_max_attempts(1);
                     auto created = client_->CreateSession(r);
                     if (!created.ok()) return FromStatus(created.status());
                     auto got = client_->GetSession(created->name());
                     (void)client_->StopSession(created->name());
                     if (!got.ok()) return FromStatus(got.status());
                     return Outcome{I, StatusCode::kOk, got->rtsp_pull().url()};
                   }});
}

TEST_F(FaultCatalogueTest, EveryItemHasItsStatusAndTheHealthySessionIsUnaffected) {
  // The healthy camera: ffmpeg publishing the drive (looped) over RTSP.
  v1::Session healthy = Request();
  healthy.mutable_rtsp_push()->set_path("healthy");
  healthy.mutable_rtsp_push()->set_start_timeout_ms(10000);
  healthy.mutable_rtsp_push()->set_receive_timeout_ms(5000);
  auto cam = client_->CreateSession(healthy);
  ASSERT_TRUE(cam.ok()) << cam.status().ToString();
  ASSERT_TRUE(testing::WaitForLocalPort("tcp", testing::PortOf(cam->ingest_url()),
                                        std::chrono::seconds(5)));
  FfmpegProcess camera({"-re", "-stream_loop", "3", "-i", drive_path_, "-c", "copy", "-f", "rtsp",
                        "-rtsp_transport", "tcp", testing::PublishUrl(*cam)});
  ASSERT_TRUE(camera.started());

  std::vector<Item> items = Catalogue();
  std::string table =
      "\n| # | input | state | status | message fragment |\n|---|---|---|---|---|\n";
  for (size_t i = 0; i < items.size(); ++i) {
    const Item& item = items[i];
    const Outcome got = item.run();
    EXPECT_EQ(got.state, item.want_state) << item.input << ": " << got.message;
    EXPECT_EQ(got.code, item.want_code) << item.input << ": " << got.message;
    EXPECT_NE(got.message.find(item.fragment), std::string::npos)
        << item.input << ": '" << got.message << "' lacks '" << item.fragment << "'";
    table += "| " + std::to_string(i + 1) + " | " + item.input + " | " +
             (item.want_state == v1::Session::STATE_UNSPECIFIED
                  ? "(rpc)"
                  : v1::Session::State_Name(item.want_state)) +
             " | " +
             // core's StatusCodeName stops at DATA_LOSS (15); gRPC's 16 is named here.
             (got.code == server::kUnauthenticated ? "UNAUTHENTICATED" : StatusCodeName(got.code)) +
             " | " + got.message.substr(0, 110) + " |\n";
  }
  std::printf("%s", table.c_str());
  EXPECT_GE(items.size(), 40u);

  // The healthy session streamed throughout and finished with its poses.
  EXPECT_EQ(camera.Wait(std::chrono::seconds(30)), 0);
  const Outcome end = EndOf(cam->name());
  EXPECT_EQ(end.state, v1::Session::FINISHED) << end.message;
  auto traj = client_->GetTrajectory(cam->name());
  ASSERT_TRUE(traj.ok()) << traj.status().ToString();
  EXPECT_GT(traj->points_size(), 20);
  auto got = client_->GetSession(cam->name());
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->stats().reconnects(), 0);
  EXPECT_GT(got->stats().frames(), 100);
}

}  // namespace
}  // namespace slapse
