// The server's log: one line per record on stderr, as text or as JSON lines.
//
//   text: 2026-11-23T14:03:05.123Z INFO  sessions/3 state: RUNNING: receiving the stream
//   json: {"time":"2026-11-23T14:03:05.123Z","level":"info","session":"sessions/3",
//          "event":"state","message":"RUNNING: receiving the stream"}
//
// `session` is empty for records of the server as a whole. FFmpeg's own log
// (av_log) is routed here too (event "ffmpeg"), tagged with the session whose
// thread logged it (LogSessionScope). Messages never carry credentials: every
// URL in a record is passed through api::RedactUrl.
//
// Thread-safety: every function may be called from any thread; a record is
// written with one fwrite, so records never interleave.
#pragma once

#include <cstdio>
#include <string>

namespace slapse::server {

enum class LogFormat { kText, kJson };
enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };

struct LogOptions {
  LogFormat format = LogFormat::kText;
  // Records below this level are dropped (FFmpeg's own level, av_log_set_level,
  // filters its records first).
  LogLevel min_level = LogLevel::kInfo;
};

// "text" or "json"; INVALID_ARGUMENT-style message in *error otherwise.
bool ParseLogFormat(const std::string& text, LogFormat* format, std::string* error);

// Sets the format and level for the whole process and routes FFmpeg's log
// through Log (av_log_set_callback). Call once at startup, before threads log.
void ConfigureLog(const LogOptions& options);

// Writes one record (if level >= min_level).
void Log(LogLevel level, const std::string& session, const std::string& event,
         const std::string& message);

// One record as it would be written, newline included (for tests and Log).
std::string FormatLogRecord(LogFormat format, LogLevel level, const std::string& session,
                            const std::string& event, const std::string& message);

// `text` with every URL (scheme://...) passed through api::RedactUrl.
std::string RedactUrls(const std::string& text);

// Names the session whose work runs on this thread while in scope, for the
// records logged from it without a session (FFmpeg's).
class LogSessionScope {
 public:
  explicit LogSessionScope(const std::string& session);
  ~LogSessionScope();
  LogSessionScope(const LogSessionScope&) = delete;
  LogSessionScope& operator=(const LogSessionScope&) = delete;

 private:
  std::string previous_;
};

// The session named by the innermost LogSessionScope on this thread ("" if none).
const std::string& CurrentLogSession();

}  // namespace slapse::server
