// Fuzzes the upload byte queue (server/upload_queue.h) with arbitrary
// sequences of producer and consumer operations, as an UploadStream rpc and
// a session's MvReader issue them, all on one thread: the input is a list of
// operations (write a chunk of N bytes, finish, close, read up to N bytes).
// Operations that would block (a read of an empty open queue, a write into a
// full one) are either skipped or cancelled through the `cancelled` callback.
//
// Invariants checked against a model (a plain string of the bytes written):
//  - reads return exactly the written bytes, in order, never more than asked;
//  - after Finish, reads drain the buffered bytes then return 0 (end);
//  - after Close, reads return -1 and writes return the close reason
//    (the first reason given);
//  - total_bytes() is the sum of the accepted writes; a write past
//    max_total_bytes is RESOURCE_EXHAUSTED and closes the queue.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "server/upload_queue.h"

namespace {

void Check(bool ok, const char* what) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_upload_queue: invariant violated: %s\n", what);
  std::abort();
}

struct Input {
  const uint8_t* p;
  size_t n;
  uint8_t Byte() {
    if (n == 0) return 0;
    --n;
    return *p++;
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using slapse::StatusCode;
  Input in{data, size};
  slapse::server::UploadQueueOptions options;
  options.capacity_bytes = 1 + in.Byte() * 4;
  options.max_total_bytes = in.Byte() * 16;  // 0 = no limit
  slapse::server::UploadQueue queue(options);
  const auto cancel = [] { return true; };  // a blocked write gives up at once

  std::string model;          // bytes written and not yet read
  int64_t total = 0;          // accepted bytes
  bool finished = false, closed = false;
  StatusCode close_code = StatusCode::kOk;
  uint8_t counter = 0;
  std::vector<uint8_t> buf;
  for (int ops = 0; in.n > 0 && ops < 4096; ++ops) {
    const uint8_t op = in.Byte(), arg = in.Byte();
    switch (op % 4) {
      case 0: {  // write `arg` bytes
        std::string chunk(arg, '\0');
        for (char& c : chunk) c = static_cast<char>(counter++);
        const bool full = !model.empty() &&
                          static_cast<int64_t>(model.size()) + arg > options.capacity_bytes;
        const bool over = options.max_total_bytes > 0 && total + arg > options.max_total_bytes;
        const slapse::Status s = queue.Write(chunk, cancel);
        if (closed) {
          Check(s.code() == close_code, "write after close did not return the close reason");
        } else if (finished) {
          Check(s.code() == StatusCode::kFailedPrecondition, "write after finish accepted");
        } else if (over) {
          Check(s.code() == StatusCode::kResourceExhausted, "write past the limit accepted");
          closed = true;
          close_code = StatusCode::kResourceExhausted;
          model.clear();
        } else if (full) {
          Check(s.code() == StatusCode::kCancelled, "write into a full queue did not wait");
        } else {
          Check(s.ok(), "a write with room failed");
          model += chunk;
          total += arg;
        }
        break;
      }
      case 1:
        queue.Finish();
        finished = true;
        break;
      case 2: {  // close with a reason picked by arg
        const slapse::Status reason = arg % 2 == 0 ? slapse::Status::Ok()
                                                   : slapse::DataLossError("reader failed");
        queue.Close(reason);
        if (!closed) {
          closed = true;
          close_code = reason.ok() ? StatusCode::kCancelled : StatusCode::kDataLoss;
          model.clear();
        }
        break;
      }
      case 3: {  // read up to arg + 1 bytes, unless it would block
        if (!closed && !finished && model.empty()) break;
        const int want = arg + 1;
        buf.assign(want, 0xEE);
        const int got = queue.Read(buf.data(), want);
        if (closed) {
          Check(got == -1, "read after close did not fail");
        } else if (model.empty()) {
          Check(got == 0, "read of a finished, drained queue did not end");
        } else {
          Check(got > 0 && got <= want, "read size out of range");
          Check(got == static_cast<int>(std::min<size_t>(want, model.size())),
                "read returned fewer bytes than buffered");
          Check(model.compare(0, got, reinterpret_cast<const char*>(buf.data()), got) == 0,
                "read bytes differ from the written ones");
          model.erase(0, got);
        }
        break;
      }
    }
    Check(queue.total_bytes() == total, "total_bytes() differs from the accepted bytes");
  }
  return 0;
}
