#include "client/cli/flags.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "api/validate.h"
#include "client/cli/commands.h"
#include "core/common/intrinsics_io.h"
#include "server/server.h"

namespace slapse::cli {

CommandLine::CommandLine(const std::string& command, const std::string& synopsis,
                         const std::string& positional_name)
    : command_(command), app_("usage: slapse " + command + " " + synopsis, "slapse " + command) {
  app_.add_option(positional_name, positional_, "")->group("");  // the synopsis shows them
  // Unknown options are collected and reported by Parse, before --help.
  app_.allow_extras();
  // A switch takes no value: --quiet=1 is a usage error, as it always was.
  app_.option_defaults()->disable_flag_override();
}

namespace {

// The first unknown option among CLI11's leftovers, or "".
std::string UnknownOption(const std::vector<std::string>& remaining) {
  for (const std::string& arg : remaining) {
    if (arg.rfind("-", 0) == 0 && arg != "-") return arg.substr(0, arg.find('='));
  }
  return remaining.empty() ? "" : remaining.front();
}

}  // namespace

int CommandLine::Parse(int argc, char** argv) {
  // CLI11 takes the arguments of a vector last to first.
  std::vector<std::string> args(argv, argv + argc);
  std::reverse(args.begin(), args.end());
  bool help = false;
  try {
    app_.parse(args);
  } catch (const CLI::CallForHelp&) {
    help = true;
  } catch (const CLI::ParseError& e) {
    return Fail(command_.c_str(), std::string(e.what()) + " (see 'slapse " + command_ + " --help')",
                2);
  }
  if (const std::string unknown = UnknownOption(app_.remaining()); !unknown.empty()) {
    return Fail(command_.c_str(),
                "unknown option " + unknown + " (see 'slapse " + command_ + " --help')", 2);
  }
  if (help) {
    std::printf("%s", app_.help().c_str());
    return 0;
  }
  return -1;
}

bool CommandLine::Has(const std::string& name) const { return app_.count("--" + name) > 0; }

Status CheckRange(const std::string& name, double v, double min, double max) {
  if (v >= min && v <= max) return Status::Ok();
  std::ostringstream os;
  os << "--" << name << " must be in [" << min << ", " << max << "], got " << v;
  return InvalidArgumentError(os.str());
}

Status CheckRange(const std::string& name, int64_t v, int64_t min, int64_t max) {
  if (v >= min && v <= max) return Status::Ok();
  return InvalidArgumentError("--" + name + " must be in [" + std::to_string(min) + ", " +
                              std::to_string(max) + "], got " + std::to_string(v));
}

void AddTrackingFlags(CommandLine* command_line, PipelineOptions* options) {
  CLI::App& app = command_line->app();
  app.add_option("--window-refine", options->window_refine,
                 "sliding-window refinement of poses and planes (PipelineOptions::window_refine, "
                 "docs/METHOD.md)")
      ->type_name("BOOL")
      ->capture_default_str();
  app.add_option("--refine-window", options->refine.window_anchors,
                 "anchors in the refinement window (WindowRefinerOptions::window_anchors)")
      ->type_name("N")
      ->capture_default_str();
  app.add_option("--road-attitude-sigma-deg", options->refine.road_attitude_sigma_deg,
                 "the refinement's prior on the road's attitude in the camera, per axis; 0 = off "
                 "(WindowRefinerOptions::road_attitude_sigma_deg)")
      ->type_name("DEG")
      ->check(CLI::Range(0.0, api::kMaxRoadAttitudeSigmaDeg))
      ->capture_default_str();
  app.add_option("--motion-only-steps", options->motion_only_steps,
                 "track pairs with motion but no plane from their rotation and direction "
                 "(PipelineOptions::motion_only_steps)")
      ->type_name("BOOL")
      ->capture_default_str();
  app.add_option("--road-from-frames", options->road_from_frames,
                 "B-frame streams: measure the road from the B frames next to the earlier anchor "
                 "where the anchor pair does not show it (PipelineOptions::road_from_frames)")
      ->type_name("BOOL")
      ->capture_default_str();
  app.add_option("--min-pair-span-s", options->merge.min_pair_span_s,
                 "IPPP streams: chain P frames until an anchor pair spans at least this long; "
                 "0 = one pair per P frame (MergeOptions::min_pair_span_s)")
      ->type_name("S")
      ->check(CLI::Range(0.0, api::kMaxMinPairSpanS))
      ->capture_default_str();
}

void ScaleFlags::AddTo(CommandLine* command_line) {
  command_line_ = command_line;
  CLI::App& app = command_line->app();
  app.add_option("--first-step-m", first_step_m_, "metric scale: length of the first tracked step")
      ->type_name("M");
  app.add_option("--speed-kmh", speed_kmh_, "metric scale: speed at the start")->type_name("V");
  app.add_option("--camera-height-m", camera_height_m_,
                 "metric scale: camera height above the road plane")
      ->type_name("H");
}

StatusOr<ScaleOptions> ScaleFlags::Options() const {
  ScaleOptions scale;
  int sources = 0;
  if (command_line_->Has("first-step-m")) {
    SLAPSE_RETURN_IF_ERROR(CheckRange("first-step-m", first_step_m_, 1e-3, 1e3));
    scale.source = ScaleOptions::Source::kFirstStep;
    scale.first_step_m = first_step_m_;
    ++sources;
  }
  if (command_line_->Has("speed-kmh")) {
    SLAPSE_RETURN_IF_ERROR(CheckRange("speed-kmh", speed_kmh_, 0.1, 500));
    scale.source = ScaleOptions::Source::kSpeed;
    scale.speed_mps = speed_kmh_ / 3.6;
    ++sources;
  }
  if (command_line_->Has("camera-height-m")) {
    SLAPSE_RETURN_IF_ERROR(CheckRange("camera-height-m", camera_height_m_, 0.05, 100));
    scale.source = ScaleOptions::Source::kCameraHeight;
    scale.camera_height_m = camera_height_m_;
    ++sources;
  }
  if (sources > 1) return InvalidArgumentError("give at most one scale source");
  return scale;
}

StatusOr<Intrinsics> IntrinsicsFor(const std::string& spec, const std::string& input, int width_px,
                                   int height_px) {
  if (!spec.empty()) return ParseIntrinsicsSpec(spec, width_px, height_px);
  const auto beside = std::filesystem::path(input).parent_path() / "intrinsics.json";
  if (!std::filesystem::exists(beside)) {
    return InvalidArgumentError(
        "--intrinsics is required (FILE.json, 'fx,fy,cx,cy' or 'hfov=DEG'): no intrinsics.json "
        "beside " +
        input);
  }
  return ParseIntrinsicsSpec(beside.string(), width_px, height_px);
}

namespace {

// What AddServerFlag's security flags were given (one command per process).
client::ClientOptions& ConnectionFlags() {
  static client::ClientOptions options;
  return options;
}

}  // namespace

void AddServerFlag(CommandLine* command_line, std::string* server) {
  *server = "localhost:" + std::to_string(server::ServerOptions{}.port);
  CLI::App& app = command_line->app();
  app.add_option("--server", *server, "the slapse server")
      ->type_name("HOST:PORT")
      ->capture_default_str();
  client::ClientOptions& o = ConnectionFlags();
  app.add_flag("--tls", o.tls, "talk TLS to the server (serve --tls-cert)");
  app.add_option("--ca", o.tls_ca_file,
                 "with --tls: PEM of the CA that signed the server's certificate (default: the "
                 "system's roots)")
      ->type_name("FILE");
  app.add_option("--cert", o.tls_cert_file,
                 "with --tls: this client's certificate (PEM), for a server with --tls-client-ca")
      ->type_name("FILE");
  app.add_option("--key", o.tls_key_file, "with --cert: its private key (PEM)")->type_name("FILE");
  app.add_option("--token", o.token,
                 "bearer token for a server with --tokens-file (default: $SLAPSE_TOKEN; the "
                 "variable keeps it out of the process list and shell history)")
      ->type_name("TOKEN");
}

StatusOr<client::ClientOptions> ServerConnection() {
  client::ClientOptions o = ConnectionFlags();
  if (o.token.empty()) {
    const char* env = std::getenv("SLAPSE_TOKEN");
    if (env != nullptr) o.token = env;
  }
  SLAPSE_RETURN_IF_ERROR(o.Check());
  return o;
}

}  // namespace slapse::cli
