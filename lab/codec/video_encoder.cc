#include "lab/codec/video_encoder.h"

#include <cmath>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

namespace slapse {
namespace {

std::string AvErr(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(err, buf, sizeof(buf));
  return buf;
}

const char* EncoderName(VideoCodec codec) {
  switch (codec) {
    case VideoCodec::kMpeg2:
      return "mpeg2video";
    case VideoCodec::kMpeg4:
      return "mpeg4";
    case VideoCodec::kH264:
      return "libx264";
    case VideoCodec::kHevc:
      return "libx265";
    case VideoCodec::kVp9:
      return "libvpx-vp9";
    case VideoCodec::kMjpeg:
      return "mjpeg";
  }
  return "";
}

}  // namespace

const char* VideoCodecName(VideoCodec codec) {
  switch (codec) {
    case VideoCodec::kMpeg2:
      return "mpeg2";
    case VideoCodec::kMpeg4:
      return "mpeg4";
    case VideoCodec::kH264:
      return "h264";
    case VideoCodec::kHevc:
      return "hevc";
    case VideoCodec::kVp9:
      return "vp9";
    case VideoCodec::kMjpeg:
      return "mjpeg";
  }
  return "";
}

StatusOr<VideoCodec> ParseVideoCodec(const std::string& name) {
  if (name == "mpeg2" || name == "mpeg2video") return VideoCodec::kMpeg2;
  if (name == "mpeg4") return VideoCodec::kMpeg4;
  if (name == "h264" || name == "libx264") return VideoCodec::kH264;
  if (name == "hevc" || name == "h265" || name == "libx265") return VideoCodec::kHevc;
  if (name == "vp9" || name == "libvpx-vp9") return VideoCodec::kVp9;
  if (name == "mjpeg") return VideoCodec::kMjpeg;
  return InvalidArgumentError("unknown codec '" + name +
                              "' (expected mpeg2, mpeg4, h264, hevc, vp9 or mjpeg)");
}

namespace {

constexpr int kPresetGopSecondsChoices[] = {1, 2, 4, 10};
constexpr char kBaselinePrefix[] = "h264-baseline-ippp-";
constexpr char kLowRatePreset[] = "h264-baseline-ippp-2s-lowrate";
// 2 Mbit/s at 640x480.
constexpr double kCameraBitsPerPixelS = 2e6 / (640.0 * 480.0);

}  // namespace

std::vector<std::string> EncoderPresetNames() {
  std::vector<std::string> names = {"mpeg2-ibbbp", "mpeg2-interlaced", "mpeg4-ibbbp", "h264-ippp"};
  for (int s : kPresetGopSecondsChoices) {
    names.push_back(kBaselinePrefix + std::to_string(s) + "s");
  }
  names.push_back(kLowRatePreset);
  for (const char* n : {"h264-main-bpyr-3ref", "h264-high-bpyr-3ref", "h264-x264-defaults", "hevc",
                        "vp9", "mjpeg"}) {
    names.push_back(n);
  }
  return names;
}

StatusOr<EncoderOptions> EncoderPreset(const std::string& name, double fps) {
  if (fps <= 0) return InvalidArgumentError("preset needs a positive fps");
  const auto frames_in = [fps](double s) {
    return std::max(1, static_cast<int>(std::lround(s * fps)));
  };
  EncoderOptions o;
  o.fps = fps;
  if (name == "mpeg2-ibbbp" || name == "mpeg4-ibbbp") {
    o.codec = name == "mpeg2-ibbbp" ? VideoCodec::kMpeg2 : VideoCodec::kMpeg4;
    return o;  // IBBBP, GOP 12, quantiser 4: EncoderOptions{}
  }
  if (name == "mpeg2-interlaced") {
    o.interlaced = true;
    return o;
  }
  o.quality = 20;  // CRF for x264 / x265 / VP9; MJPEG's quantiser is set below
  if (name == "h264-ippp") {
    o.codec = VideoCodec::kH264;
    o.b_frames = 0;
    return o;
  }
  if (name == kLowRatePreset) {
    o.codec = VideoCodec::kH264;
    o.h264_profile = "baseline";
    o.b_frames = 0;
    o.gop_size = frames_in(2);
    o.h264_bits_per_pixel_s = kCameraBitsPerPixelS;
    return o;
  }
  if (name.rfind(kBaselinePrefix, 0) == 0) {
    for (int s : kPresetGopSecondsChoices) {
      if (name != kBaselinePrefix + std::to_string(s) + "s") continue;
      o.codec = VideoCodec::kH264;
      o.h264_profile = "baseline";
      o.b_frames = 0;
      o.gop_size = frames_in(s);
      return o;
    }
  }
  if (name == "h264-main-bpyr-3ref" || name == "h264-high-bpyr-3ref") {
    o.codec = VideoCodec::kH264;
    o.h264_profile = name == "h264-main-bpyr-3ref" ? "main" : "high";
    o.b_frames = 3;
    o.h264_b_pyramid = true;
    o.h264_refs = 3;
    o.gop_size = frames_in(2);
    return o;
  }
  if (name == "h264-x264-defaults") {
    o.codec = VideoCodec::kH264;
    o.h264_x264_defaults = true;
    return o;
  }
  if (name == "hevc" || name == "vp9") {
    o.codec = name == "hevc" ? VideoCodec::kHevc : VideoCodec::kVp9;
    o.gop_size = frames_in(2);
    o.quality = name == "hevc" ? 23 : 32;
    return o;
  }
  if (name == "mjpeg") {
    o.codec = VideoCodec::kMjpeg;
    o.b_frames = 0;
    o.gop_size = 1;
    o.quality = 4;
    return o;
  }
  std::string all;
  for (const std::string& n : EncoderPresetNames()) all += (all.empty() ? "" : ", ") + n;
  return InvalidArgumentError("unknown encoder preset '" + name + "' (expected one of " + all +
                              ")");
}

VideoEncoder::~VideoEncoder() {
  if (!finished_ && mux_ != nullptr && mux_->pb != nullptr &&
      !(mux_->oformat->flags & AVFMT_NOFILE)) {
    avio_closep(&mux_->pb);
  }
  sws_freeContext(sws_);
  av_packet_free(&pkt_);
  av_frame_free(&yuv_);
  avcodec_free_context(&enc_);
  avformat_free_context(mux_);
}

StatusOr<std::unique_ptr<VideoEncoder>> VideoEncoder::Open(const std::string& path, int width_px,
                                                           int height_px, const EncoderOptions& o) {
  if (width_px <= 0 || height_px <= 0 || width_px % 2 != 0 || height_px % 2 != 0) {
    return InvalidArgumentError("frame size must be positive and even, got " +
                                std::to_string(width_px) + "x" + std::to_string(height_px));
  }
  if (o.fps <= 0) return InvalidArgumentError("fps must be positive");
  if (o.b_frames < 0 || o.b_frames > 16) return InvalidArgumentError("b_frames must be 0..16");
  if (o.gop_size < 1) return InvalidArgumentError("gop_size must be >= 1");
  if (o.h264_bits_per_pixel_s < 0 ||
      (o.h264_bits_per_pixel_s > 0 && o.codec != VideoCodec::kH264)) {
    return InvalidArgumentError("h264_bits_per_pixel_s must be >= 0, and is for H.264 only");
  }
  if (o.interlaced && o.codec != VideoCodec::kMpeg2) {
    return InvalidArgumentError(std::string("interlaced encoding is MPEG-2 only, not ") +
                                VideoCodecName(o.codec));
  }
  std::unique_ptr<VideoEncoder> e(new VideoEncoder());
  e->path_ = path;
  int err = avformat_alloc_output_context2(&e->mux_, nullptr, nullptr, path.c_str());
  if (err < 0 || e->mux_ == nullptr) {
    return InvalidArgumentError("no container for '" + path + "': " + AvErr(err));
  }
  const AVCodec* codec = avcodec_find_encoder_by_name(EncoderName(o.codec));
  if (codec == nullptr) {
    return FailedPreconditionError(std::string("FFmpeg has no encoder '") + EncoderName(o.codec) +
                                   "'");
  }
  e->enc_ = avcodec_alloc_context3(codec);
  AVCodecContext* c = e->enc_;
  c->width = width_px;
  c->height = height_px;
  c->pix_fmt = o.codec == VideoCodec::kMjpeg ? AV_PIX_FMT_YUVJ420P : AV_PIX_FMT_YUV420P;
  c->framerate = av_d2q(o.fps, 100000);
  c->time_base = av_inv_q(c->framerate);
  c->gop_size = o.gop_size;
  c->max_b_frames = o.b_frames;
  c->thread_count = 1;  // deterministic output for a given input
  if (e->mux_->oformat->flags & AVFMT_GLOBALHEADER) c->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;

  AVDictionary* opts = nullptr;
  if (o.codec == VideoCodec::kH264) {
    av_dict_set(&opts, "preset", o.h264_x264_defaults ? "medium" : "veryfast", 0);
    if (o.h264_bits_per_pixel_s > 0) {
      // A camera's rate control: the average at the cap, a 1 s buffer.
      c->bit_rate = std::llround(o.h264_bits_per_pixel_s * width_px * height_px);
      c->rc_max_rate = c->bit_rate;
      c->rc_buffer_size = static_cast<int>(c->bit_rate);
    } else {
      av_dict_set_int(&opts, "crf", o.quality, 0);
    }
    if (o.h264_x264_defaults) {
      // x264's own GOP, B frames and references (-1: libx264 keeps its default).
      c->gop_size = -1;
      c->max_b_frames = -1;
    } else {
      // Fixed GOP: no adaptive B placement and no scene cuts; by default no
      // B-pyramid and one reference, so every B frame refers to its two
      // neighbouring anchors (the reading of MVs in docs/METHOD.md, "MV merging").
      const std::string params =
          std::string("scenecut=0:b-adapt=0:b-pyramid=") + (o.h264_b_pyramid ? "normal" : "none") +
          ":ref=" + std::to_string(std::max(1, o.h264_refs)) +
          ":bframes=" + std::to_string(o.b_frames) + ":keyint=" + std::to_string(o.gop_size) +
          ":min-keyint=" + std::to_string(o.gop_size);
      av_dict_set(&opts, "x264-params", params.c_str(), 0);
    }
    if (!o.h264_profile.empty()) av_dict_set(&opts, "profile", o.h264_profile.c_str(), 0);
  } else if (o.codec == VideoCodec::kHevc) {
    // A camera's HEVC: x265's own B frames and references, a fixed GOP.
    av_dict_set(&opts, "preset", "ultrafast", 0);
    av_dict_set_int(&opts, "crf", o.quality, 0);
    const std::string params = "log-level=error:scenecut=0:keyint=" + std::to_string(o.gop_size) +
                               ":min-keyint=" + std::to_string(o.gop_size) +
                               ":bframes=" + std::to_string(o.b_frames) +
                               ":pools=1:frame-threads=1";
    av_dict_set(&opts, "x265-params", params.c_str(), 0);
  } else if (o.codec == VideoCodec::kVp9) {
    av_dict_set(&opts, "deadline", "realtime", 0);
    av_dict_set(&opts, "cpu-used", "8", 0);
    av_dict_set_int(&opts, "crf", o.quality, 0);
    c->bit_rate = 0;
  } else {
    if (o.quality < 1 || o.quality > 31) {
      avcodec_free_context(&e->enc_);
      return InvalidArgumentError("MPEG quantiser must be 1..31");
    }
    c->flags |= AV_CODEC_FLAG_QSCALE;
    c->global_quality = FF_QP2LAMBDA * o.quality;
    av_dict_set(&opts, "sc_threshold", "1000000000", 0);  // no scene-cut I frames
    av_dict_set(&opts, "b_strategy", "0", 0);             // always max_b_frames B frames
    // A wider motion search than the defaults (diamond 1, 1 predictor): the
    // near road of a driving video moves 20-40 px a frame.
    av_dict_set(&opts, "dia_size", "4", 0);
    av_dict_set(&opts, "last_pred", "3", 0);
    if (o.codec == VideoCodec::kMpeg4 && o.mpeg4_qpel) c->flags |= AV_CODEC_FLAG_QPEL;
    if (o.interlaced) {
      c->flags |= AV_CODEC_FLAG_INTERLACED_ME | AV_CODEC_FLAG_INTERLACED_DCT;
      c->field_order = AV_FIELD_TT;
    }
    if (o.codec == VideoCodec::kMjpeg) c->max_b_frames = 0;
  }
  err = avcodec_open2(c, codec, &opts);
  av_dict_free(&opts);
  if (err < 0)
    return InvalidArgumentError("cannot open encoder " + std::string(codec->name) + ": " +
                                AvErr(err));

  e->stream_ = avformat_new_stream(e->mux_, nullptr);
  if (e->stream_ == nullptr) return ResourceExhaustedError("cannot add a stream");
  e->stream_->time_base = c->time_base;
  err = avcodec_parameters_from_context(e->stream_->codecpar, c);
  if (err < 0) return InternalError("codec parameters: " + AvErr(err));
  if (!(e->mux_->oformat->flags & AVFMT_NOFILE)) {
    err = avio_open(&e->mux_->pb, path.c_str(), AVIO_FLAG_WRITE);
    if (err < 0) return UnavailableError("cannot write '" + path + "': " + AvErr(err));
  }
  err = avformat_write_header(e->mux_, nullptr);
  if (err < 0) return InternalError("cannot write the container header: " + AvErr(err));

  e->yuv_ = av_frame_alloc();
  e->pkt_ = av_packet_alloc();
  e->yuv_->format = c->pix_fmt;
  e->yuv_->width = width_px;
  e->yuv_->height = height_px;
  err = av_frame_get_buffer(e->yuv_, 0);
  if (err < 0) return ResourceExhaustedError("frame buffer: " + AvErr(err));
  e->sws_ = sws_getContext(width_px, height_px, AV_PIX_FMT_BGR24, width_px, height_px, c->pix_fmt,
                           SWS_BICUBIC, nullptr, nullptr, nullptr);
  if (e->sws_ == nullptr) return InternalError("cannot create the colour converter");
  return StatusOr<std::unique_ptr<VideoEncoder>>(std::move(e));
}

Status VideoEncoder::Write(const cv::Mat& bgr) {
  if (finished_) return FailedPreconditionError("encoder already finished");
  if (bgr.type() != CV_8UC3 || bgr.cols != enc_->width || bgr.rows != enc_->height) {
    return InvalidArgumentError("frame must be 8-bit BGR of " + std::to_string(enc_->width) + "x" +
                                std::to_string(enc_->height));
  }
  int err = av_frame_make_writable(yuv_);
  if (err < 0) return InternalError("frame not writable: " + AvErr(err));
  const uint8_t* src[1] = {bgr.data};
  const int stride[1] = {static_cast<int>(bgr.step[0])};
  sws_scale(sws_, src, stride, 0, bgr.rows, yuv_->data, yuv_->linesize);
  yuv_->pts = frames_++;
  // Interlaced: each frame's top field first (mpeg2video reads the order per frame).
  yuv_->interlaced_frame = (enc_->flags & AV_CODEC_FLAG_INTERLACED_ME) != 0;
  yuv_->top_field_first = yuv_->interlaced_frame;
  if (enc_->flags & AV_CODEC_FLAG_QSCALE) yuv_->quality = enc_->global_quality;
  err = avcodec_send_frame(enc_, yuv_);
  if (err < 0) return InternalError("encoding failed: " + AvErr(err));
  return Drain(false);
}

Status VideoEncoder::Drain(bool flush) {
  while (true) {
    int err = avcodec_receive_packet(enc_, pkt_);
    if (err == AVERROR(EAGAIN) && !flush) return Status::Ok();
    if (err == AVERROR_EOF) return Status::Ok();
    if (err < 0) return InternalError("encoding failed: " + AvErr(err));
    av_packet_rescale_ts(pkt_, enc_->time_base, stream_->time_base);
    pkt_->stream_index = stream_->index;
    err = av_interleaved_write_frame(mux_, pkt_);  // takes ownership of pkt_'s data
    if (err < 0) return UnavailableError("cannot write '" + path_ + "': " + AvErr(err));
  }
}

Status VideoEncoder::Finish() {
  if (finished_) return Status::Ok();
  finished_ = true;
  int err = avcodec_send_frame(enc_, nullptr);
  if (err < 0) return InternalError("flushing failed: " + AvErr(err));
  SLAPSE_RETURN_IF_ERROR(Drain(true));
  err = av_write_trailer(mux_);
  if (err < 0) return UnavailableError("cannot finish '" + path_ + "': " + AvErr(err));
  if (!(mux_->oformat->flags & AVFMT_NOFILE)) avio_closep(&mux_->pb);
  return Status::Ok();
}

}  // namespace slapse
