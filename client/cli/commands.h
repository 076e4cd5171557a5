// The slapse CLI's subcommands. Each takes the arguments after its name and
// returns the process exit code; errors are printed as one line on stderr.
#pragma once

#include <string>

namespace slapse::cli {

int RunMvs(int argc, char** argv);
int RunSimulate(int argc, char** argv);
int RunPlanes(int argc, char** argv);
int RunEvalPlanes(int argc, char** argv);
int RunRun(int argc, char** argv);
// The service (cmd_service.cc).
int RunServe(int argc, char** argv);
int RunCreate(int argc, char** argv);
int RunUpload(int argc, char** argv);
int RunWatch(int argc, char** argv);
int RunList(int argc, char** argv);
int RunGet(int argc, char** argv);
int RunStop(int argc, char** argv);
int RunDelete(int argc, char** argv);
int RunExport(int argc, char** argv);  // cmd_export.cc
int RunHealth(int argc, char** argv);  // cmd_health.cc
// The trajectory yardstick (cmd_eval_trajectory.cc).
int RunEvalTrajectory(int argc, char** argv);

// Prints "slapse <command>: <message>" on stderr and returns 1 (or 2 for usage errors).
int Fail(const char* command, const std::string& message, int code = 1);

}  // namespace slapse::cli
