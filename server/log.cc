#include "server/log.h"

#include <atomic>
#include <chrono>
#include <cstdarg>
#include <ctime>

extern "C" {
#include <libavutil/log.h>
}

#include "api/validate.h"
#include "core/common/json_io.h"

namespace slapse::server {
namespace {

std::atomic<int> g_format{static_cast<int>(LogFormat::kText)};
std::atomic<int> g_min_level{static_cast<int>(LogLevel::kInfo)};
thread_local std::string t_session;

const char* LevelName(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarning:
      return "warning";
    case LogLevel::kError:
      break;
  }
  return "error";
}

// RFC 3339 UTC with milliseconds: 2026-11-23T14:03:05.123Z
std::string NowRfc3339() {
  const auto now = std::chrono::system_clock::now();
  const std::time_t t = std::chrono::system_clock::to_time_t(now);
  const int ms = static_cast<int>(
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[40];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
  return std::string(buf) + "." + (ms < 100 ? (ms < 10 ? "00" : "0") : "") + std::to_string(ms) +
         "Z";
}

LogLevel FromAvLevel(int level) {
  if (level <= AV_LOG_ERROR) return LogLevel::kError;
  if (level <= AV_LOG_WARNING) return LogLevel::kWarning;
  if (level <= AV_LOG_INFO) return LogLevel::kInfo;
  return LogLevel::kDebug;
}

// FFmpeg logs a line in pieces; each thread gathers its pieces until '\n'.
void AvLogCallback(void* avcl, int level, const char* fmt, va_list vl) {
  if (level > av_log_get_level()) return;
  thread_local std::string line;
  thread_local int print_prefix = 1;
  char buf[1024];
  av_log_format_line2(avcl, level, fmt, vl, buf, sizeof buf, &print_prefix);
  line += buf;
  if (line.empty() || line.back() != '\n') return;
  line.pop_back();
  if (!line.empty()) Log(FromAvLevel(level), t_session, "ffmpeg", line);
  line.clear();
}

}  // namespace

bool ParseLogFormat(const std::string& text, LogFormat* format, std::string* error) {
  if (text == "text") {
    *format = LogFormat::kText;
  } else if (text == "json") {
    *format = LogFormat::kJson;
  } else {
    *error = "log format must be 'text' or 'json', got '" + text + "'";
    return false;
  }
  return true;
}

void ConfigureLog(const LogOptions& options) {
  g_format = static_cast<int>(options.format);
  g_min_level = static_cast<int>(options.min_level);
  av_log_set_callback(AvLogCallback);
}

std::string RedactUrls(const std::string& text) {
  std::string out;
  size_t pos = 0;
  for (;;) {
    const size_t sep = text.find("://", pos);
    if (sep == std::string::npos) break;
    // The URL runs from its scheme (letters, digits, + - .) to the next blank or quote.
    size_t begin = sep;
    while (begin > pos &&
           (std::isalnum(static_cast<unsigned char>(text[begin - 1])) || text[begin - 1] == '+' ||
            text[begin - 1] == '-' || text[begin - 1] == '.')) {
      --begin;
    }
    size_t end = text.find_first_of(" \t\r\n'\"<>", sep);
    if (end == std::string::npos) end = text.size();
    out += text.substr(pos, begin - pos);
    out += api::RedactUrl(text.substr(begin, end - begin));
    pos = end;
  }
  return out + text.substr(pos);
}

std::string FormatLogRecord(LogFormat format, LogLevel level, const std::string& session,
                            const std::string& event, const std::string& message) {
  const std::string time = NowRfc3339();
  const std::string safe = RedactUrls(message);
  if (format == LogFormat::kJson) {
    Json doc;
    doc["time"] = time;
    doc["level"] = LevelName(level);
    doc["session"] = session;
    doc["event"] = event;
    doc["message"] = safe;
    // No floating-point members: the number format is never asked.
    return DumpJsonLine(doc, ExactNumber) + "\n";
  }
  char level_col[8];
  std::snprintf(level_col, sizeof level_col, "%-7s", LevelName(level));
  std::string line = time + " " + level_col + " ";
  if (!session.empty()) line += session + " ";
  return line + event + ": " + safe + "\n";
}

void Log(LogLevel level, const std::string& session, const std::string& event,
         const std::string& message) {
  if (static_cast<int>(level) < g_min_level.load()) return;
  const std::string record =
      FormatLogRecord(static_cast<LogFormat>(g_format.load()), level, session, event, message);
  std::fwrite(record.data(), 1, record.size(), stderr);
}

LogSessionScope::LogSessionScope(const std::string& session) : previous_(t_session) {
  t_session = session;
}

LogSessionScope::~LogSessionScope() { t_session = previous_; }

const std::string& CurrentLogSession() { return t_session; }

}  // namespace slapse::server
