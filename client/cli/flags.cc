#include "client/cli/flags.h"

#include "core/common/intrinsics_io.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>

namespace slapse::cli {

const FlagSpec* Flags::Find(const std::string& name) const {
  for (const FlagSpec& s : specs_) {
    if (s.name == name) return &s;
  }
  return nullptr;
}

Status Flags::Parse(int argc, char** argv) {
  for (int i = 0; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      help_ = true;
      continue;
    }
    if (arg.rfind("--", 0) != 0 || arg == "--") {
      positional_.push_back(arg);
      continue;
    }
    std::string name = arg.substr(2), value;
    bool has_value = false;
    if (const size_t eq = name.find('='); eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
      has_value = true;
    }
    const FlagSpec* spec = Find(name);
    if (spec == nullptr) {
      return InvalidArgumentError("unknown option --" + name + " (see 'slapse " + command_ +
                                  " --help')");
    }
    if (spec->meta.empty()) {
      if (has_value) return InvalidArgumentError("--" + name + " takes no value");
      values_[name] = "1";
      continue;
    }
    if (!has_value) {
      if (i + 1 >= argc) return InvalidArgumentError("--" + name + " needs a value " + spec->meta);
      value = argv[++i];
    }
    values_[name] = value;
  }
  return Status::Ok();
}

std::string Flags::Usage() const {
  std::ostringstream os;
  os << "usage: slapse " << command_ << " " << synopsis_ << "\n\noptions:\n";
  std::vector<FlagSpec> all = specs_;
  all.push_back({"help", "", "this text", ""});
  for (const FlagSpec& s : all) {
    std::string left = "  --" + s.name + (s.meta.empty() ? "" : " " + s.meta);
    if (left.size() < 28) left.resize(28, ' ');
    os << left << " " << s.help;
    if (!s.default_value.empty()) os << " (default " << s.default_value << ")";
    os << "\n";
  }
  return os.str();
}

std::string Flags::GetString(const std::string& name) const {
  if (auto it = values_.find(name); it != values_.end()) return it->second;
  const FlagSpec* spec = Find(name);
  return spec != nullptr ? spec->default_value : "";
}

StatusOr<int64_t> Flags::GetInt(const std::string& name, int64_t min, int64_t max) const {
  const std::string text = GetString(name);
  errno = 0;
  char* end = nullptr;
  const long long v = std::strtoll(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || errno != 0) {
    return InvalidArgumentError("--" + name + " must be an integer, got '" + text + "'");
  }
  if (v < min || v > max) {
    return InvalidArgumentError("--" + name + " must be in [" + std::to_string(min) + ", " +
                                std::to_string(max) + "], got " + text);
  }
  return static_cast<int64_t>(v);
}

StatusOr<double> Flags::GetDouble(const std::string& name, double min, double max) const {
  const std::string text = GetString(name);
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || errno != 0 || !std::isfinite(v)) {
    return InvalidArgumentError("--" + name + " must be a number, got '" + text + "'");
  }
  if (v < min || v > max) {
    std::ostringstream os;
    os << "--" << name << " must be in [" << min << ", " << max << "], got " << text;
    return InvalidArgumentError(os.str());
  }
  return v;
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

}  // namespace slapse::cli
