// The slapse CLI's flag handling: CLI11 parses each subcommand's flags, which
// are bound straight to the core option structs (so --help shows the structs'
// defaults, never a retyped string). Positional arguments are collected and
// counted by each command, range checks print the messages they always have,
// and the scale-source flags are parsed in one place for `run` and `create`.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "client/lib/client.h"
#include "core/common/camera.h"
#include "core/common/status.h"
#include "core/pipeline/pipeline.h"

namespace slapse::cli {

// One subcommand's command line: `slapse <command> ...`.
class CommandLine {
 public:
  // `synopsis` is shown first in --help; `positional_name` names the
  // positional arguments there (e.g. "INPUT").
  CommandLine(const std::string& command, const std::string& synopsis,
              const std::string& positional_name = "ARGS");

  CLI::App& app() { return app_; }

  // Parses argv after the subcommand name. Returns -1 to go on; 0 after
  // printing --help on stdout; 2 after printing a usage error on stderr.
  int Parse(int argc, char** argv);

  const std::vector<std::string>& positional() const { return positional_; }
  // Whether --`name` was given on the command line.
  bool Has(const std::string& name) const;
  const char* command() const { return command_.c_str(); }

 private:
  std::string command_;
  CLI::App app_;
  std::vector<std::string> positional_;
};

// "--name must be in [min, max], got v" unless min <= v <= max (NaN fails).
Status CheckRange(const std::string& name, double v, double min, double max);
Status CheckRange(const std::string& name, int64_t v, int64_t min, int64_t max);

// --server HOST:PORT (the client commands), default: this machine on the
// server's default port (ServerOptions). It also adds how to reach the
// server: --tls, --ca FILE, --cert FILE, --key FILE and --token TOKEN
// (default: the SLAPSE_TOKEN environment variable), which ServerConnection()
// returns after parsing (one command runs per process).
void AddServerFlag(CommandLine* command_line, std::string* server);

// The client options those flags ask for (TLS, files, token), or the usage
// error (ClientOptions::Check); timeouts are the library's defaults.
StatusOr<client::ClientOptions> ServerConnection();

// The metric-scale flags shared by `run` and `create`: --first-step-m,
// --speed-kmh, --camera-height-m (at most one).
class ScaleFlags {
 public:
  void AddTo(CommandLine* command_line);
  // The ScaleOptions they ask for (default: up to scale), or the usage error.
  StatusOr<ScaleOptions> Options() const;

 private:
  CommandLine* command_line_ = nullptr;
  double first_step_m_ = 0.0, speed_kmh_ = 0.0, camera_height_m_ = 0.0;
};

// The tracking flags shared by `run` and `eval-trajectory`, bound to
// `options`: --window-refine, --refine-window, --road-attitude-sigma-deg,
// --motion-only-steps and --min-pair-span-s (range-checked as the wire
// options are, api/validate.h).
void AddTrackingFlags(CommandLine* command_line, PipelineOptions* options);

// Intrinsics for a width x height stream from an --intrinsics spec
// (ParseIntrinsicsSpec), or, when `spec` is empty, from the simulator's
// intrinsics.json beside `input`.
StatusOr<Intrinsics> IntrinsicsFor(const std::string& spec, const std::string& input, int width_px,
                                   int height_px);

}  // namespace slapse::cli
