// The upload source: the bytes of the session's one UploadStream, through its
// bounded UploadQueue (server/upload_queue.h), demuxed as they arrive. No
// deadlines (the client paces it); the stream ends at the end of the upload,
// or with the upload's own error if the client cancelled it or sent too much.
#include "server/ingest_source.h"

namespace slapse::server {
namespace {

class UploadSource : public SingleConnectionSource {
 public:
  explicit UploadSource(std::shared_ptr<UploadQueue> upload)
      : SingleConnectionSource(0, 0), upload_(std::move(upload)) {}

  bool network() const override { return false; }

  StatusOr<std::unique_ptr<MvReader>> Open(std::function<bool()> interrupt) override {
    MvReaderOptions o = ReaderOptions(std::move(interrupt));
    return MvReader::Open(std::make_unique<UploadByteSource>(upload_), o);
  }

  // The queue's own reason wins over what the reader made of it (-1 reads
  // as a damaged stream): an idle timeout, a cancelled or too large upload.
  std::optional<int> AfterConnection(Session* session, const ConnectionEnd& end) override {
    const Status reason = upload_->close_reason();
    if (!reason.ok()) {
      session->EndStream(reason, EndOfStreamMessage());
      return std::nullopt;
    }
    return SingleConnectionSource::AfterConnection(session, end);
  }

 protected:
  // Never called: an upload has no deadline.
  Ending TimedOut(int64_t) const override { return {}; }

 private:
  std::shared_ptr<UploadQueue> upload_;
};

}  // namespace

std::unique_ptr<IngestSource> MakeUploadSource(std::shared_ptr<UploadQueue> upload) {
  return std::make_unique<UploadSource>(std::move(upload));
}

}  // namespace slapse::server
