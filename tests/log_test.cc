// server/log.h: the text and JSON-lines records, URL redaction, and FFmpeg's
// own log (av_log) routed through it with the session of the logging thread.
#include "server/log.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

extern "C" {
#include <libavutil/log.h>
}

#include "core/common/json_io.h"
#include "tests/test_streams.h"

namespace slapse::server {
namespace {

TEST(LogTest, JsonRecordHasTheFiveFieldsOnOneLine) {
  const std::string line = FormatLogRecord(LogFormat::kJson, LogLevel::kWarning, "sessions/3",
                                           "state", "FAILED: \"quoted\"\nnext line");
  ASSERT_FALSE(line.empty());
  EXPECT_EQ(line.back(), '\n');
  EXPECT_EQ(line.find('\n'), line.size() - 1) << "one record, one line";
  auto doc = ParseJsonText(line, "record");
  ASSERT_TRUE(doc.ok()) << doc.status().ToString();
  EXPECT_EQ((*doc)["level"], "warning");
  EXPECT_EQ((*doc)["session"], "sessions/3");
  EXPECT_EQ((*doc)["event"], "state");
  EXPECT_EQ((*doc)["message"], "FAILED: \"quoted\"\nnext line");
  const std::string time = (*doc)["time"];
  // RFC 3339 UTC with milliseconds: 2026-11-23T14:03:05.123Z
  ASSERT_EQ(time.size(), 24u) << time;
  EXPECT_EQ(time[10], 'T');
  EXPECT_EQ(time[19], '.');
  EXPECT_EQ(time.back(), 'Z');
}

TEST(LogTest, TextRecordNamesSessionAndEvent) {
  const std::string line =
      FormatLogRecord(LogFormat::kText, LogLevel::kInfo, "sessions/9", "state", "RUNNING");
  EXPECT_NE(line.find(" info "), std::string::npos) << line;
  EXPECT_NE(line.find(" sessions/9 state: RUNNING\n"), std::string::npos) << line;
  const std::string server_line =
      FormatLogRecord(LogFormat::kText, LogLevel::kError, "", "serve", "bound");
  EXPECT_NE(server_line.find(" error   serve: bound\n"), std::string::npos) << server_line;
}

TEST(LogTest, RecordsNeverCarryCredentials) {
  const std::string message =
      "connect to rtsp://admin:hunter2@10.0.0.7:554/live failed, "
      "then 'rtsps://u:p4ss@cam/x' and http://nobody@h/ and a plain rtsp://cam/1";
  const std::string redacted = RedactUrls(message);
  EXPECT_EQ(redacted,
            "connect to rtsp://***@10.0.0.7:554/live failed, then 'rtsps://***@cam/x' and "
            "http://***@h/ and a plain rtsp://cam/1");
  for (LogFormat f : {LogFormat::kText, LogFormat::kJson}) {
    const std::string line = FormatLogRecord(f, LogLevel::kError, "", "ffmpeg", message);
    EXPECT_EQ(line.find("hunter2"), std::string::npos) << line;
    EXPECT_EQ(line.find("p4ss"), std::string::npos) << line;
  }
}

TEST(LogTest, ParseLogFormat) {
  LogFormat f = LogFormat::kText;
  std::string error;
  EXPECT_TRUE(ParseLogFormat("json", &f, &error));
  EXPECT_EQ(f, LogFormat::kJson);
  EXPECT_TRUE(ParseLogFormat("text", &f, &error));
  EXPECT_EQ(f, LogFormat::kText);
  EXPECT_FALSE(ParseLogFormat("xml", &f, &error));
  EXPECT_NE(error.find("'text' or 'json'"), std::string::npos) << error;
}

// Runs `body` with stderr sent to a file; returns what was written.
template <typename Body>
std::string CaptureStderr(Body body) {
  const std::string path = testing::MakeTempDir("log_test") + "/stderr.txt";
  std::fflush(stderr);
  const int saved = dup(2);
  const int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  dup2(fd, 2);
  close(fd);
  body();
  std::fflush(stderr);
  dup2(saved, 2);
  close(saved);
  return testing::ReadFileBytes(path);
}

TEST(LogTest, FfmpegLogIsRoutedWithTheThreadsSession) {
  const int old_level = av_log_get_level();
  av_log_set_level(AV_LOG_WARNING);
  const std::string out = CaptureStderr([] {
    ConfigureLog({LogFormat::kJson, LogLevel::kInfo});
    {
      LogSessionScope scope("sessions/7");
      // A line in two pieces, as FFmpeg writes many.
      av_log(nullptr, AV_LOG_ERROR, "cannot open %s: ", "rtsp://user:s3cret@cam:8554/x");
      av_log(nullptr, AV_LOG_ERROR, "Connection refused\n");
      av_log(nullptr, AV_LOG_VERBOSE, "below FFmpeg's level: dropped\n");
      av_log(nullptr, AV_LOG_WARNING, "a warning\n");
    }
    av_log(nullptr, AV_LOG_ERROR, "outside any session\n");
    EXPECT_EQ(CurrentLogSession(), "");
    ConfigureLog({LogFormat::kText, LogLevel::kInfo});
  });
  av_log_set_level(old_level);

  std::vector<Json> records;
  std::istringstream lines(out);
  for (std::string line; std::getline(lines, line);) {
    auto doc = ParseJsonText(line, "stderr line");
    ASSERT_TRUE(doc.ok()) << "not a JSON line: " << line;
    records.push_back(*doc);
  }
  ASSERT_EQ(records.size(), 3u) << out;
  EXPECT_EQ(records[0]["session"], "sessions/7");
  EXPECT_EQ(records[0]["event"], "ffmpeg");
  EXPECT_EQ(records[0]["level"], "error");
  EXPECT_EQ(records[0]["message"], "cannot open rtsp://***@cam:8554/x: Connection refused");
  EXPECT_EQ(records[1]["level"], "warning");
  EXPECT_EQ(records[1]["message"], "a warning");
  EXPECT_EQ(records[2]["session"], "");
  EXPECT_EQ(out.find("s3cret"), std::string::npos);
}

}  // namespace
}  // namespace slapse::server
