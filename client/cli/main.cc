// slapse: motion vectors in, trajectories and planes out.
#include <cstdio>
#include <cstring>
#include <string>

extern "C" {
#include <libavutil/log.h>
}

#include "client/cli/commands.h"

namespace slapse::cli {

int Fail(const char* command, const std::string& message, int code) {
  std::fprintf(stderr, "slapse %s: %s\n", command, message.c_str());
  return code;
}

}  // namespace slapse::cli

namespace {

struct Command {
  const char* name;
  int (*run)(int, char**);
  const char* help;
};

const Command kCommands[] = {
    {"run", slapse::cli::RunRun,
     "the main job: trajectory + plane map from a video (TUM, KITTI, JSON, map.png)"},
    {"simulate", slapse::cli::RunSimulate,
     "render a street drive with ground truth and encode it (MPEG-2/MPEG-4/H.264)"},
    {"mvs", slapse::cli::RunMvs, "read a stream's motion vectors: dump, draw, summarise"},
    {"planes", slapse::cli::RunPlanes, "extract planes and draw one anchor pair's (Fig. 5)"},
    {"eval-planes", slapse::cli::RunEvalPlanes,
     "plane extraction TP rate and recall on simulated drives (Table I)"},
    {"serve", slapse::cli::RunServe, "run the gRPC server (sessions, upload, live watch)"},
    {"create", slapse::cli::RunCreate, "create a session on a server (--upload)"},
    {"upload", slapse::cli::RunUpload, "send a video file as a session's stream"},
    {"watch", slapse::cli::RunWatch, "follow a session's poses, planes and state (resumable)"},
    {"list", slapse::cli::RunList, "list a server's sessions"},
    {"get", slapse::cli::RunGet, "show one session with its statistics"},
    {"stop", slapse::cli::RunStop, "stop a session (keeps its results)"},
    {"delete", slapse::cli::RunDelete, "stop and forget a session"},
    {"export", slapse::cli::RunExport,
     "a session's trajectory / plane map from a server as TUM, KITTI or JSON files"},
    {"health", slapse::cli::RunHealth,
     "ask a server's gRPC health service whether a service is SERVING (exit 0)"},
    {"eval-trajectory", slapse::cli::RunEvalTrajectory,
     "the trajectory yardstick: every scene kind, tuning / reporting drives, per codec"},
};

void PrintUsage(FILE* out) {
  std::fprintf(out, "usage: slapse COMMAND [options]   ('slapse COMMAND --help' for details)\n\n");
  for (const Command& c : kCommands) std::fprintf(out, "  %-12s %s\n", c.name, c.help);
}

}  // namespace

int main(int argc, char** argv) {
  av_log_set_level(AV_LOG_ERROR);  // decoder chatter is not for users; errors are
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h") ||
      !std::strcmp(argv[1], "help")) {
    PrintUsage(argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  for (const Command& c : kCommands) {
    if (std::strcmp(argv[1], c.name) == 0) return c.run(argc - 2, argv + 2);
  }
  std::fprintf(stderr, "slapse: unknown command '%s'\n", argv[1]);
  PrintUsage(stderr);
  return 2;
}
