#include "core/mv/mv_reader.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <set>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/dict.h>
#include <libavutil/motion_vector.h>
#include <libswscale/swscale.h>
}

#include "core/mv/mb_texture.h"
#include "core/mv/mpeg2_syntax.h"

namespace slapse {
namespace {

constexpr int kAvioBufferBytes = 64 * 1024;

std::string AvErrorString(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(err, buf, sizeof(buf));
  return buf;
}

PictureType ToPictureType(AVPictureType t) {
  switch (t) {
    case AV_PICTURE_TYPE_I:
    case AV_PICTURE_TYPE_SI:
      return PictureType::kI;
    case AV_PICTURE_TYPE_P:
    case AV_PICTURE_TYPE_SP:
    case AV_PICTURE_TYPE_S:  // MPEG-4 GMC: predicted from the past anchor
      return PictureType::kP;
    case AV_PICTURE_TYPE_B:
    case AV_PICTURE_TYPE_BI:
      return PictureType::kB;
    default:
      return PictureType::kUnknown;
  }
}

// Codecs whose FFmpeg decoders fill AV_FRAME_DATA_MOTION_VECTORS with export_mvs.
const std::set<std::string>& MvCodecs() {
  static const std::set<std::string> codecs = {"mpeg1video", "mpeg2video", "mpeg4",
                                               "h263",       "h263p",      "h264"};
  return codecs;
}

// Maps an avformat_open_input failure to a status a person can act on.
Status OpenError(const std::string& url, int err) {
  const std::string what = "cannot open '" + url + "': " + AvErrorString(err);
  if (err == AVERROR(ENOENT)) return NotFoundError(what);
  if (err == AVERROR_EXIT) return CancelledError(what + " (interrupted)");
  if (err == AVERROR_INVALIDDATA || err == AVERROR_DEMUXER_NOT_FOUND ||
      err == AVERROR_PROTOCOL_NOT_FOUND || err == AVERROR(EINVAL)) {
    return InvalidArgumentError(what);
  }
  if (err == AVERROR(EACCES) || err == AVERROR(EPERM)) {
    return Status(StatusCode::kPermissionDenied, what);
  }
  return UnavailableError(what);
}

// True if `data` holds an MPEG-2 picture coding extension whose
// picture_structure is a field (core/mv/mpeg2_syntax.h).
bool HasFieldPicture(const uint8_t* data, int size) {
  const size_t n = size > 0 ? static_cast<size_t>(size) : 0;
  for (size_t i = FindMpeg2PictureCodingExtension(data, n); i < n;
       i = FindMpeg2PictureCodingExtension(data, n, i + 1)) {
    const int structure = data[i + kMpeg2PictureStructureByte] & 3;
    if (structure == kMpeg2TopField || structure == kMpeg2BottomField) return true;
  }
  return false;
}

}  // namespace

char PictureTypeChar(PictureType type) {
  switch (type) {
    case PictureType::kI:
      return 'I';
    case PictureType::kP:
      return 'P';
    case PictureType::kB:
      return 'B';
    default:
      return '?';
  }
}

bool CodecExportsMotionVectors(const std::string& codec_name) {
  return MvCodecs().count(codec_name) > 0;
}

MvReader::~MvReader() {
  av_frame_free(&frame_);
  av_frame_free(&reencoded_);
  av_packet_free(&pkt_);
  avcodec_free_context(&dec_);
  avformat_close_input(&fmt_);
  if (avio_ != nullptr) {
    av_freep(&avio_->buffer);
    avio_context_free(&avio_);
  }
}

int MvReader::InterruptTrampoline(void* opaque) {
  auto* self = static_cast<MvReader*>(opaque);
  return self->options_.interrupt && self->options_.interrupt() ? 1 : 0;
}

int MvReader::ReadTrampoline(void* opaque, uint8_t* buf, int size) {
  auto* self = static_cast<MvReader*>(opaque);
  const int n = self->source_->Read(buf, size);
  if (n > 0) return n;
  return n == 0 ? AVERROR_EOF : AVERROR(EIO);
}

StatusOr<std::unique_ptr<MvReader>> MvReader::Open(const std::string& url,
                                                   const MvReaderOptions& options) {
  if (url.empty()) return InvalidArgumentError("empty input path or URL");
  return OpenImpl(std::unique_ptr<MvReader>(new MvReader()), url, options);
}

StatusOr<std::unique_ptr<MvReader>> MvReader::Open(std::unique_ptr<ByteSource> source,
                                                   const MvReaderOptions& options) {
  if (source == nullptr) return InvalidArgumentError("null byte source");
  std::unique_ptr<MvReader> reader(new MvReader());
  reader->source_ = std::move(source);
  auto* buffer = static_cast<unsigned char*>(av_malloc(kAvioBufferBytes));
  if (buffer == nullptr) return ResourceExhaustedError("out of memory for the I/O buffer");
  reader->avio_ = avio_alloc_context(buffer, kAvioBufferBytes, /*write_flag=*/0, reader.get(),
                                     &MvReader::ReadTrampoline, nullptr, nullptr);
  if (reader->avio_ == nullptr) {
    av_free(buffer);
    return ResourceExhaustedError("out of memory for the I/O context");
  }
  return OpenImpl(std::move(reader), "<byte stream>", options);
}

StatusOr<std::unique_ptr<MvReader>> MvReader::OpenImpl(std::unique_ptr<MvReader> r,
                                                       const std::string& url,
                                                       const MvReaderOptions& options) {
  r->options_ = options;
  r->fmt_ = avformat_alloc_context();
  if (r->fmt_ == nullptr) return ResourceExhaustedError("out of memory for the format context");
  r->fmt_->interrupt_callback.callback = &MvReader::InterruptTrampoline;
  r->fmt_->interrupt_callback.opaque = r.get();
  if (r->avio_ != nullptr) {
    r->fmt_->pb = r->avio_;
    r->fmt_->flags |= AVFMT_FLAG_CUSTOM_IO;
  }

  const AVInputFormat* iformat = nullptr;
  if (!options.format.empty()) {
    iformat = av_find_input_format(options.format.c_str());
    if (iformat == nullptr) {
      return InvalidArgumentError("unknown input format '" + options.format + "'");
    }
  }
  AVDictionary* fmt_opts = nullptr;
  for (const auto& [k, v] : options.format_options) av_dict_set(&fmt_opts, k.c_str(), v.c_str(), 0);
  if (options.probe_bytes > 0) av_dict_set_int(&fmt_opts, "probesize", options.probe_bytes, 0);
  const std::string open_url = r->avio_ != nullptr ? "" : url;
  int err = avformat_open_input(&r->fmt_, open_url.c_str(), iformat, &fmt_opts);
  av_dict_free(&fmt_opts);
  if (err < 0) return OpenError(url, err);  // avformat_open_input freed fmt_

  err = avformat_find_stream_info(r->fmt_, nullptr);
  if (err < 0) {
    if (err == AVERROR_EXIT) return CancelledError("interrupted while probing '" + url + "'");
    return InvalidArgumentError("cannot read stream info of '" + url + "': " + AvErrorString(err));
  }
  const int si = av_find_best_stream(r->fmt_, AVMEDIA_TYPE_VIDEO, -1, -1, nullptr, 0);
  if (si < 0) return InvalidArgumentError("'" + url + "' has no video stream");
  r->stream_index_ = si;
  AVStream* st = r->fmt_->streams[si];
  const AVCodecParameters* par = st->codecpar;
  const AVCodecDescriptor* desc = avcodec_descriptor_get(par->codec_id);
  const std::string codec_name = desc != nullptr ? desc->name : "unknown";
  const bool reencode = !CodecExportsMotionVectors(codec_name);
  if (reencode && !options.reencode) {
    return FailedPreconditionError(
        "video codec '" + codec_name + "' of '" + url +
        "' does not export motion vectors in FFmpeg and re-encoding is off; slapse reads "
        "MPEG-1/2, MPEG-4 Part 2, H.263 and H.264 directly and other codecs by re-encoding "
        "them (turn re-encoding on, or configure the camera for H.264)");
  }
  if (reencode) SLAPSE_RETURN_IF_ERROR(options.reencode_options.Check());
  const AVCodec* codec = avcodec_find_decoder(par->codec_id);
  if (codec == nullptr) {
    return FailedPreconditionError("this FFmpeg build has no decoder for '" + codec_name + "'");
  }
  r->dec_ = avcodec_alloc_context3(codec);
  if (r->dec_ == nullptr) return ResourceExhaustedError("out of memory for the decoder");
  err = avcodec_parameters_to_context(r->dec_, par);
  if (err < 0) return InternalError("bad codec parameters: " + AvErrorString(err));
  r->dec_->thread_count = std::max(1, options.decoder_threads);
  AVDictionary* dec_opts = nullptr;
  if (!reencode) av_dict_set(&dec_opts, "flags2", "+export_mvs", 0);
  if (!reencode && options.reduced_decode) r->dec_->skip_loop_filter = AVDISCARD_ALL;
  err = avcodec_open2(r->dec_, codec, &dec_opts);
  av_dict_free(&dec_opts);
  if (err < 0) {
    return FailedPreconditionError("cannot open the " + codec_name +
                                   " decoder: " + AvErrorString(err));
  }
  r->pkt_ = av_packet_alloc();
  r->frame_ = av_frame_alloc();
  r->reencoded_ = av_frame_alloc();
  if (r->pkt_ == nullptr || r->frame_ == nullptr || r->reencoded_ == nullptr) {
    return ResourceExhaustedError("out of memory");
  }

  r->time_base_s_ = av_q2d(st->time_base);
  StreamInfo& info = r->info_;
  info.codec_name = codec_name;
  if (reencode) {
    // The vectors come from the re-encoder (opened at the first frame, when
    // its size is certain); the stream's facts below are the re-encoder's.
    info.reencoded_from = codec_name;
    info.codec_name = kReencodeCodec;
  }
  info.format_name = r->fmt_->iformat != nullptr ? r->fmt_->iformat->name : "";
  info.width_px = par->width;
  info.height_px = par->height;
  const AVRational rate = st->avg_frame_rate.num > 0 ? st->avg_frame_rate : st->r_frame_rate;
  info.fps = rate.num > 0 && rate.den > 0 ? av_q2d(rate) : 0.0;
  // H.264 is quarter-pel; MPEG-1/2 and H.263 half-pel; MPEG-4 Part 2 is
  // half-pel unless the stream uses quarter_sample, seen from the first MV.
  info.mv_precision_denom = info.codec_name == "h264" ? 4 : 2;
  info.b_frame_mvs =
      info.codec_name != "mpeg4" && info.codec_name != "h263" && info.codec_name != "h263p";
  return StatusOr<std::unique_ptr<MvReader>>(std::move(r));
}

void MvReader::NoteError(const std::string& what) {
  if (stats_.first_error.empty()) stats_.first_error = what;
}

void MvReader::CollectVectors(const AVFrame* f, FrameRecord* rec) {
  const AVFrameSideData* sd = av_frame_get_side_data(f, AV_FRAME_DATA_MOTION_VECTORS);
  if (rec->type == PictureType::kB && !info_.b_frame_mvs) sd = nullptr;
  if (sd == nullptr) return;
  // In an MPEG-2 frame picture FFmpeg exports a field-predicted macroblock as
  // two 16x8 blocks (top field's vector, bottom field's), vertical component
  // doubled to frame lines but without the reference field: an opposite-parity
  // reference is a line and half a frame interval away, which the vector does
  // not say. Frame-predicted macroblocks are 16x16 (docs/METHOD.md, "MV reader").
  const bool mpeg2 = info_.codec_name == "mpeg2video";
  const auto* mvs = reinterpret_cast<const AVMotionVector*>(sd->data);
  const size_t n = sd->size / sizeof(AVMotionVector);
  rec->mvs.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const AVMotionVector& m = mvs[i];
    if (m.motion_scale == 0) continue;
    if (m.dst_y - m.h / 2 >= f->height || m.dst_x - m.w / 2 >= f->width) {
      ++stats_.outside_mvs_dropped;  // a padded macroblock row, wholly outside the picture
      continue;
    }
    if (mpeg2 && m.h == 8) {
      if (stats_.field_mvs_dropped++ == 0) {
        stats_.notes.push_back("frame " + std::to_string(rec->index) +
                               ": interlaced MPEG-2 with field prediction; field-predicted "
                               "vectors are dropped (FFmpeg does not export their reference "
                               "field), frame-predicted ones are read");
      }
      continue;
    }
    MotionVector mv;
    // FFmpeg's dst is the block centre with integer pixel edges; shift to pixel centres.
    // After a resolution change with the aspect kept, positions and
    // displacements are scaled to the first frame's grid (pixel centres:
    // x0 + 0.5 = s (x + 0.5)), as the intrinsics scaled to this size would.
    mv.x_px = static_cast<float>(scale_x_ * m.dst_x - 0.5);
    mv.y_px = static_cast<float>(scale_y_ * m.dst_y - 0.5);
    mv.dx_px = static_cast<float>(scale_x_ * m.motion_x / m.motion_scale);
    mv.dy_px = static_cast<float>(scale_y_ * m.motion_y / m.motion_scale);
    mv.w_px = m.w;
    mv.h_px = m.h;
    mv.direction = m.source > 0 ? RefDirection::kFuture : RefDirection::kPast;
    if (m.motion_scale >= 4) info_.mv_precision_denom = std::max(info_.mv_precision_denom, 4);
    rec->mvs.push_back(mv);
  }
}

void MvReader::Collect(AVFrame* f) {
  FrameRecord rec;
  rec.index = stats_.frames++;
  rec.type = ToPictureType(f->pict_type);
  const int64_t pts = f->best_effort_timestamp;
  if (pts != AV_NOPTS_VALUE) {
    if (first_pts_ == INT64_MIN) first_pts_ = pts;
    rec.timestamp_s = static_cast<double>(pts - first_pts_) * time_base_s_;
  } else if (info_.fps > 0) {
    rec.timestamp_s = static_cast<double>(rec.index) / info_.fps;
  }
  rec.corrupt = f->decode_error_flags != 0 || (f->flags & AV_FRAME_FLAG_CORRUPT) != 0;
  rec.coded_index = f->coded_picture_number;
  if (reencoder_ == nullptr) info_.max_ref_frames = std::max(info_.max_ref_frames, dec_->refs);
  if (rec.corrupt) {
    ++stats_.corrupt_frames;
    char where[96];
    std::snprintf(where, sizeof(where), "frame %lld at %.3f s decoded with concealed errors",
                  static_cast<long long>(rec.index), rec.timestamp_s);
    NoteError(where);
  }

  if (f->interlaced_frame) info_.interlaced = true;
  CollectVectors(f, &rec);

  // (Not after a resolution change: the plane would not be the stream's size.)
  if (options_.keep_luma && f->data[0] != nullptr && f->width == base_width_px_ &&
      f->height == base_height_px_ && (!options_.luma_wanted || options_.luma_wanted())) {
    rec.luma.resize(static_cast<size_t>(f->width) * f->height);
    for (int y = 0; y < f->height; ++y) {
      std::memcpy(rec.luma.data() + static_cast<size_t>(y) * f->width,
                  f->data[0] + static_cast<ptrdiff_t>(y) * f->linesize[0], f->width);
    }
  }

  if (options_.mb_texture && IsAnchor(rec.type) && f->data[0] != nullptr &&
      f->width == base_width_px_ && f->height == base_height_px_) {
    rec.mb_texture = MbTextureMinEigen(f->data[0], f->linesize[0], f->width, f->height);
  }

  // A P frame's past vectors refer to its previous anchor only when the
  // stream keeps no more references than its GOP needs (H.264 may choose any
  // of them per block; FFmpeg does not say which).
  // (As StreamInfo::extra_references(), counting the B frames before this anchor.)
  const int needed_refs =
      (std::max(info_.max_consecutive_b, consecutive_b_) > 0 ? 2 : 1) + (info_.b_pyramid ? 1 : 0);
  if (rec.type == PictureType::kP && info_.max_ref_frames > needed_refs) {
    rec.reference_certain = false;
  }
  if (rec.type == PictureType::kB && info_.b_pyramid) rec.reference_certain = false;

  // GOP bookkeeping: B frames wait in pending_ until their next anchor is decoded.
  rec.prev_anchor_index = last_anchor_index_;
  if (!IsAnchor(rec.type)) {
    if (rec.type == PictureType::kB) {
      ++consecutive_b_;
      // Between two anchors, B frames that are only predicted are decoded in
      // display order; one decoded before an earlier-shown B is a reference.
      for (const FrameRecord& b : pending_) {
        if (b.type == PictureType::kB && rec.coded_index >= 0 && b.coded_index > rec.coded_index) {
          info_.b_pyramid = true;
        }
      }
    }
    pending_.push_back(std::move(rec));
    return;
  }
  for (FrameRecord& b : pending_) {
    b.next_anchor_index = rec.index;
    ready_.push_back(std::move(b));
  }
  pending_.clear();
  info_.max_consecutive_b = std::max(info_.max_consecutive_b, consecutive_b_);
  consecutive_b_ = 0;
  last_anchor_index_ = rec.index;
  ready_.push_back(std::move(rec));
}

Status MvReader::StartReencoding(const std::string& why) {
  SLAPSE_RETURN_IF_ERROR(options_.reencode_options.Check());
  info_.reencoded_from = info_.codec_name;
  info_.codec_name = kReencodeCodec;
  info_.mv_precision_denom = 2;
  info_.b_frame_mvs = true;
  stats_.notes.push_back(why);
  return Status::Ok();
}

void MvReader::CheckPictureStructure(const AVPacket* packet) {
  if (info_.field_pictures || info_.codec_name != "mpeg2video" || !info_.reencoded_from.empty() ||
      !HasFieldPicture(packet->data, packet->size)) {
    return;
  }
  info_.field_pictures = true;
  info_.interlaced = true;
  const std::string what =
      "MPEG-2 field pictures (each field coded as a picture of its own): FFmpeg exports their "
      "vectors without the field they refer to, so they cannot be read in frame pixels";
  if (stats_.frames > 0) {
    return Fail(FailedPreconditionError(
        what + "; they begin after " + std::to_string(stats_.frames) +
        " frames read from frame pictures, and the stream ends there (the poses so far are kept)"));
  }
  if (!options_.reencode) {
    return Fail(FailedPreconditionError(what + ", and re-encoding is off (turn it on to read "
                                               "such a stream through the re-encoder)"));
  }
  if (Status s = StartReencoding(what + "; the stream is re-encoded for its vectors"); !s.ok()) {
    Fail(s);
  }
}

void MvReader::Fail(Status status) {
  if (input_status_.ok()) input_status_ = std::move(status);
  input_done_ = true;
  decoder_done_ = true;
}

namespace {

std::string SizeString(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

}  // namespace

bool MvReader::CheckFrameSize(const AVFrame* f) {
  if (base_width_px_ == 0) {
    // The size the pipeline's intrinsics are for: the stream's, or (RTP opened
    // before its sender) the first frame's.
    base_width_px_ = info_.width_px > 0 ? info_.width_px : f->width;
    base_height_px_ = info_.height_px > 0 ? info_.height_px : f->height;
    info_.width_px = base_width_px_;
    info_.height_px = base_height_px_;
    cur_width_px_ = base_width_px_;
    cur_height_px_ = base_height_px_;
  }
  if (f->width == cur_width_px_ && f->height == cur_height_px_) return true;
  const int64_t index = stats_.frames;
  char when[64];
  std::snprintf(when, sizeof(when), "frame %lld", static_cast<long long>(index));
  const std::string change = std::string(when) + ": the stream's size changed from " +
                             SizeString(cur_width_px_, cur_height_px_) + " to " +
                             SizeString(f->width, f->height);
  const double sx = static_cast<double>(base_width_px_) / f->width;
  const double sy = static_cast<double>(base_height_px_) / f->height;
  // Aspect kept: the two scales agree within 1 % (rounding of odd sizes).
  if (f->width <= 0 || f->height <= 0 || std::abs(sx / sy - 1.0) > 0.01) {
    Fail(FailedPreconditionError(
        change + ", a different aspect ratio than the intrinsics' " +
        SizeString(base_width_px_, base_height_px_) +
        ": the intrinsics cannot be rescaled to it, so the stream ends here (the trajectory up "
        "to here is kept); start a new session with intrinsics for the new size"));
    return false;
  }
  cur_width_px_ = f->width;
  cur_height_px_ = f->height;
  scale_x_ = sx;
  scale_y_ = sy;
  if (reencoder_ != nullptr) {
    // The re-encoder scales the image itself (below): its vectors stay on the first grid.
    scale_x_ = scale_y_ = 1.0;
  }
  stats_.notes.push_back(change + " (aspect kept): intrinsics rescaled, vectors read on the " +
                         SizeString(base_width_px_, base_height_px_) + " grid");
  return true;
}

void MvReader::DrainReencoder() {
  for (;;) {
    const int err = reencoder_->Receive(reencoded_);
    if (err == AVERROR(EAGAIN) || err == AVERROR_EOF) return;
    if (err < 0) {
      Fail(InternalError("decoding the re-encoded frames failed: " + AvErrorString(err)));
      return;
    }
    Collect(reencoded_);
    av_frame_unref(reencoded_);
  }
}

void MvReader::Take(AVFrame* f) {
  if (!input_status_.ok() && decoder_done_) return;  // the stream already ended
  if (!CheckFrameSize(f)) return;
  if (!info_.reencoded_from.empty()) {
    if (reencoder_ == nullptr) {
      auto opened = Reencoder::Open(base_width_px_, base_height_px_, options_.reencode_options);
      if (!opened.ok()) return Fail(opened.status());
      reencoder_ = std::move(*opened);
    }
    const AVFrame* in = f;
    AVFrame* scaled = nullptr;
    if (f->width != base_width_px_ || f->height != base_height_px_) {
      // Aspect kept (CheckFrameSize): the image back to the first size, so the
      // intrinsics hold; the re-encoder converts, this only scales.
      scaled = av_frame_alloc();
      scaled->format = f->format;
      scaled->width = base_width_px_;
      scaled->height = base_height_px_;
      SwsContext* sws =
          sws_getContext(f->width, f->height, static_cast<AVPixelFormat>(f->format), base_width_px_,
                         base_height_px_, static_cast<AVPixelFormat>(f->format), SWS_BILINEAR,
                         nullptr, nullptr, nullptr);
      if (sws == nullptr || av_frame_get_buffer(scaled, 0) < 0) {
        sws_freeContext(sws);
        av_frame_free(&scaled);
        return Fail(InternalError("cannot rescale a frame for re-encoding"));
      }
      sws_scale(sws, f->data, f->linesize, 0, f->height, scaled->data, scaled->linesize);
      sws_freeContext(sws);
      in = scaled;
    }
    const Status sent = reencoder_->Send(in, f->best_effort_timestamp);
    av_frame_free(&scaled);
    if (!sent.ok()) return Fail(sent);
    stats_.reencode_cpu_s = reencoder_->cpu_s();
    DrainReencoder();
    stats_.reencode_cpu_s = reencoder_->cpu_s();
    return;
  }
  Collect(f);
}

void MvReader::EndInput(int err) {
  input_done_ = true;
  if (err == AVERROR_EOF && options_.check_source_at_end) {
    const int answer = av_read_pause(fmt_);  // 0: the source answered
    if (answer == AVERROR_EXIT) {
      err = answer;
    } else if (answer < 0) {
      input_status_ = UnavailableError(
          "the connection was lost after " + std::to_string(stats_.packets) +
          " packets: the input ended without an end of stream and the source no longer answers");
      return;
    }
  }
  if (err == AVERROR_EXIT) {
    input_status_ = CancelledError("reading was interrupted");
  } else if (err != AVERROR_EOF) {
    input_status_ = UnavailableError("input failed after " + std::to_string(stats_.packets) +
                                     " packets: " + AvErrorString(err));
  }
}

Status MvReader::Pump() {
  while (ready_.empty() && !decoder_done_) {
    // Drain every frame the decoder has ready.
    int err;
    {
      ScopedCpuTimer timer(&stats_.decode_cpu_s);
      err = avcodec_receive_frame(dec_, frame_);
    }
    if (err >= 0) {
      Take(frame_);
      av_frame_unref(frame_);
      continue;
    }
    if (err == AVERROR_EOF) {
      decoder_done_ = true;
      if (reencoder_ != nullptr && input_status_.ok()) {
        if (Status s = reencoder_->Send(nullptr, 0); !s.ok()) {
          Fail(s);
        } else {
          DrainReencoder();
        }
      }
      break;
    }
    if (err != AVERROR(EAGAIN)) {
      ++stats_.packet_errors;
      NoteError("decoder failed: " + AvErrorString(err));
      continue;
    }
    // The decoder needs input.
    if (input_done_) {
      // Already flushing: nothing more will come.
      decoder_done_ = true;
      break;
    }
    err = av_read_frame(fmt_, pkt_);
    if (err < 0) {
      EndInput(err);
      avcodec_send_packet(dec_, nullptr);  // enter draining mode
      continue;
    }
    if (pkt_->stream_index == stream_index_) {
      ++stats_.packets;
      CheckPictureStructure(pkt_);
      if (decoder_done_) {  // refused (field pictures)
        av_packet_unref(pkt_);
        break;
      }
      if ((pkt_->flags & AV_PKT_FLAG_CORRUPT) != 0) {
        NoteError("packet " + std::to_string(stats_.packets) + " is marked corrupt by the demuxer");
        ++stats_.packet_errors;
      }
      {
        ScopedCpuTimer timer(&stats_.decode_cpu_s);
        err = avcodec_send_packet(dec_, pkt_);
      }
      if (err < 0 && err != AVERROR(EAGAIN)) {
        ++stats_.packet_errors;
        NoteError("packet " + std::to_string(stats_.packets) +
                  " failed to decode: " + AvErrorString(err));
      }
    }
    av_packet_unref(pkt_);
  }
  if (decoder_done_ && !pending_.empty()) {
    // The stream ended between a B frame and its next anchor.
    for (FrameRecord& b : pending_) ready_.push_back(std::move(b));
    pending_.clear();
  }
  return Status::Ok();
}

Status MvReader::EndStatus() const {
  if (!input_status_.ok()) return input_status_;
  if (stats_.packet_errors > 0 || stats_.corrupt_frames > 0) {
    return DataLossError("stream damaged: " + std::to_string(stats_.packet_errors) +
                         " packet error(s), " + std::to_string(stats_.corrupt_frames) +
                         " frame(s) with concealed errors out of " + std::to_string(stats_.frames) +
                         " decoded; first: " + stats_.first_error);
  }
  if (stats_.frames == 0) return DataLossError("no frame could be decoded");
  return OutOfRangeError("end of stream");
}

Status MvReader::Next(FrameRecord* frame) {
  SLAPSE_RETURN_IF_ERROR(Pump());
  if (ready_.empty()) return EndStatus();
  *frame = std::move(ready_.front());
  ready_.pop_front();
  return Status::Ok();
}

}  // namespace slapse
