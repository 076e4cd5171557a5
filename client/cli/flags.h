// A small command-line parser for slapse's subcommands: `--name value`,
// `--name=value`, boolean `--name`, positional arguments, and `--help`.
// Every accessor validates its value; errors are one line a person can act on.
#pragma once

#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/common/camera.h"
#include "core/common/status.h"

namespace slapse::cli {

struct FlagSpec {
  std::string name;  // without dashes
  std::string meta;  // value placeholder, empty for a boolean switch
  std::string help;  // one line
  std::string default_value;
};

class Flags {
 public:
  Flags(std::string command, std::string synopsis, std::vector<FlagSpec> specs)
      : command_(std::move(command)), synopsis_(std::move(synopsis)), specs_(std::move(specs)) {}

  // Parses argv after the subcommand name. `--help` sets help_requested().
  Status Parse(int argc, char** argv);
  bool help_requested() const { return help_; }
  std::string Usage() const;

  const std::vector<std::string>& positional() const { return positional_; }
  bool Has(const std::string& name) const { return values_.count(name) > 0; }
  std::string GetString(const std::string& name) const;
  StatusOr<int64_t> GetInt(const std::string& name, int64_t min, int64_t max) const;
  StatusOr<double> GetDouble(const std::string& name, double min, double max) const;
  bool GetBool(const std::string& name) const { return Has(name); }

 private:
  const FlagSpec* Find(const std::string& name) const;

  std::string command_, synopsis_;
  std::vector<FlagSpec> specs_;
  std::map<std::string, std::string> values_;
  std::vector<std::string> positional_;
  bool help_ = false;
};

// Intrinsics for a width x height stream from an --intrinsics spec
// (ParseIntrinsicsSpec), or, when `spec` is empty, from the simulator's
// intrinsics.json beside `input`.
StatusOr<Intrinsics> IntrinsicsFor(const std::string& spec, const std::string& input, int width_px,
                                   int height_px);

}  // namespace slapse::cli
