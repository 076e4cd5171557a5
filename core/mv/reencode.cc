#include "core/mv/reencode.h"

#include <ctime>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/opt.h>
#include <libavutil/pixdesc.h>
#include <libswscale/swscale.h>
}

namespace slapse {
namespace {

std::string AvErr(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(err, buf, sizeof(buf));
  return buf;
}

}  // namespace

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

Status ReencodeOptions::Check() const {
  if (quantiser < 1 || quantiser > 31)
    return InvalidArgumentError("re-encode quantiser must be 1..31");
  if (b_frames < 0 || b_frames > 16)
    return InvalidArgumentError("re-encode b_frames must be 0..16");
  if (gop_size < 1 || gop_size > 600)
    return InvalidArgumentError("re-encode gop_size must be 1..600");
  if (dia_size < -16 || dia_size > 16)
    return InvalidArgumentError("re-encode dia_size must be -16..16");
  if (last_pred < 0 || last_pred > 16)
    return InvalidArgumentError("re-encode last_pred must be 0..16");
  return Status::Ok();
}

Reencoder::~Reencoder() {
  for (AVPacket*& p : packets_) av_packet_free(&p);
  sws_freeContext(sws_);
  av_packet_free(&pkt_);
  av_frame_free(&yuv_);
  avcodec_free_context(&enc_);
  avcodec_free_context(&dec_);
}

StatusOr<std::unique_ptr<Reencoder>> Reencoder::Open(int width_px, int height_px,
                                                     const ReencodeOptions& o) {
  SLAPSE_RETURN_IF_ERROR(o.Check());
  if (width_px < 16 || height_px < 16 || width_px > 4095 || height_px > 4095) {
    return FailedPreconditionError("cannot re-encode a " + std::to_string(width_px) + "x" +
                                   std::to_string(height_px) +
                                   " stream: MPEG-2 takes 16..4095 pixels a side");
  }
  std::unique_ptr<Reencoder> r(new Reencoder());
  r->width_px_ = width_px;
  r->height_px_ = height_px;
  const AVCodec* enc = avcodec_find_encoder_by_name(kReencodeCodec);
  const AVCodec* dec = avcodec_find_decoder_by_name(kReencodeCodec);
  if (enc == nullptr || dec == nullptr) {
    return FailedPreconditionError(std::string("this FFmpeg build has no ") + kReencodeCodec +
                                   " encoder and decoder to re-encode with");
  }
  r->enc_ = avcodec_alloc_context3(enc);
  r->dec_ = avcodec_alloc_context3(dec);
  r->yuv_ = av_frame_alloc();
  r->pkt_ = av_packet_alloc();
  if (!r->enc_ || !r->dec_ || !r->yuv_ || !r->pkt_) return ResourceExhaustedError("out of memory");
  AVCodecContext* c = r->enc_;
  c->width = width_px;
  c->height = height_px;
  c->pix_fmt = AV_PIX_FMT_YUV420P;
  // The encoder's clock is a frame counter at a rate MPEG-2 knows; the source
  // timestamps travel beside it (source_pts_), so any source timing survives.
  c->framerate = AVRational{25, 1};
  c->time_base = AVRational{1, 25};
  c->gop_size = o.gop_size;
  c->max_b_frames = o.b_frames;
  c->thread_count = 1;
  c->flags |= AV_CODEC_FLAG_QSCALE;
  c->global_quality = FF_QP2LAMBDA * o.quantiser;
  c->bit_rate = 0;
  AVDictionary* opts = nullptr;
  av_dict_set(&opts, "sc_threshold", "1000000000", 0);  // no scene-cut I frames
  av_dict_set(&opts, "b_strategy", "0", 0);             // always b_frames B frames
  av_dict_set_int(&opts, "dia_size", o.dia_size, 0);
  av_dict_set_int(&opts, "last_pred", o.last_pred, 0);
  int err = avcodec_open2(c, enc, &opts);
  av_dict_free(&opts);
  if (err < 0) return InternalError("cannot open the re-encoder: " + AvErr(err));

  r->dec_->thread_count = 1;
  AVDictionary* dec_opts = nullptr;
  av_dict_set(&dec_opts, "flags2", "+export_mvs", 0);
  err = avcodec_open2(r->dec_, dec, &dec_opts);
  av_dict_free(&dec_opts);
  if (err < 0) return InternalError("cannot open the re-encoded stream's decoder: " + AvErr(err));

  r->yuv_->format = AV_PIX_FMT_YUV420P;
  r->yuv_->width = width_px;
  r->yuv_->height = height_px;
  err = av_frame_get_buffer(r->yuv_, 0);
  if (err < 0) return ResourceExhaustedError("cannot allocate a frame: " + AvErr(err));
  return StatusOr<std::unique_ptr<Reencoder>>(std::move(r));
}

Status Reencoder::DrainEncoder() {
  for (;;) {
    const int err = avcodec_receive_packet(enc_, pkt_);
    if (err == AVERROR(EAGAIN) || err == AVERROR_EOF) return Status::Ok();
    if (err < 0) return InternalError("re-encoding failed: " + AvErr(err));
    AVPacket* copy = av_packet_alloc();
    if (copy == nullptr) return ResourceExhaustedError("out of memory");
    av_packet_move_ref(copy, pkt_);
    packets_.push_back(copy);
  }
}

Status Reencoder::Send(const AVFrame* frame, int64_t source_pts) {
  ScopedCpuTimer timer(&cpu_s_);
  if (flushing_) return FailedPreconditionError("the re-encoder was flushed");
  if (frame == nullptr) {
    flushing_ = true;
    avcodec_send_frame(enc_, nullptr);
    return DrainEncoder();
  }
  if (frame->width != width_px_ || frame->height != height_px_) {
    return InvalidArgumentError(
        "re-encoder opened for " + std::to_string(width_px_) + "x" + std::to_string(height_px_) +
        " got a " + std::to_string(frame->width) + "x" + std::to_string(frame->height) + " frame");
  }
  // Any decoder output (4:2:2, 10 bit, full-range JPEG, ...) -> 4:2:0 8 bit.
  sws_ = sws_getCachedContext(sws_, frame->width, frame->height,
                              static_cast<AVPixelFormat>(frame->format), width_px_, height_px_,
                              AV_PIX_FMT_YUV420P, SWS_BILINEAR, nullptr, nullptr, nullptr);
  if (sws_ == nullptr) {
    return FailedPreconditionError(
        std::string("cannot convert pixel format ") +
        (av_get_pix_fmt_name(static_cast<AVPixelFormat>(frame->format))
             ? av_get_pix_fmt_name(static_cast<AVPixelFormat>(frame->format))
             : "?") +
        " for re-encoding");
  }
  int err = av_frame_make_writable(yuv_);
  if (err < 0) return ResourceExhaustedError("cannot write a frame: " + AvErr(err));
  sws_scale(sws_, frame->data, frame->linesize, 0, frame->height, yuv_->data, yuv_->linesize);
  yuv_->pts = next_pts_;
  yuv_->pict_type = AV_PICTURE_TYPE_NONE;
  yuv_->quality = enc_->global_quality;  // fixed quantiser (AV_CODEC_FLAG_QSCALE)
  source_pts_[next_pts_++] = source_pts;
  err = avcodec_send_frame(enc_, yuv_);
  if (err < 0) return InternalError("re-encoding failed: " + AvErr(err));
  return DrainEncoder();
}

int Reencoder::Receive(AVFrame* out) {
  ScopedCpuTimer timer(&cpu_s_);
  for (;;) {
    int err = avcodec_receive_frame(dec_, out);
    if (err == 0) {
      const auto it = source_pts_.find(out->pts);
      const int64_t pts = it != source_pts_.end() ? it->second : AV_NOPTS_VALUE;
      if (it != source_pts_.end()) source_pts_.erase(it);
      out->pts = pts;
      out->best_effort_timestamp = pts;
      return 0;
    }
    if (err != AVERROR(EAGAIN)) return err;  // AVERROR_EOF after the flush, or a failure
    if (!packets_.empty()) {
      AVPacket* p = packets_.front();
      err = avcodec_send_packet(dec_, p);
      if (err == AVERROR(EAGAIN)) continue;  // cannot happen after EAGAIN above; retry
      packets_.pop_front();
      av_packet_free(&p);
      if (err < 0) return err;
      continue;
    }
    if (flushing_ && !decoder_flushed_) {
      decoder_flushed_ = true;
      avcodec_send_packet(dec_, nullptr);
      continue;
    }
    return AVERROR(EAGAIN);
  }
}

}  // namespace slapse
