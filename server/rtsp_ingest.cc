#include "server/rtsp_ingest.h"

#include <fcntl.h>
#include <gst/app/gstappsink.h>
#include <gst/gst.h>
#include <gst/rtsp-server/rtsp-server.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/rand.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <functional>
#include <future>
#include <map>
#include <sstream>
#include <thread>
#include <vector>

#include "server/store.h"

namespace slapse::server {
namespace {

// The record pipeline of one publisher. gst-rtsp-server links the
// publisher's RTP into the element named depay0; parsebin picks the
// depayloader and parser from the SDP's caps (H.264, MPEG-4 Part 2, MPEG-2
// video) without decoding (ContinueUntilParsed). MPEG-TS keeps each frame's
// timestamps. The
// appsink's callbacks (OnNewSample) feed the session's byte queue; max-buffers
// and drop bound what a refused second publisher's pipeline could hold.
// alignment=7: 7 TS packets (1316 bytes) per buffer. mpegtsmux's default
// pushed each 188-byte packet on its own, a sample, a copy and a byte-queue
// write each: 157 551 samples for a 20 s 12 Mbit/s camera, 22 508 with 7
// (counted in OnNewSample). The server's CPU
// per stream second (service_bench, 4 sessions, runs alternated) went
// 0.233 / 0.225 -> 0.226 / 0.212 s; larger buffers would hold a low-bitrate
// camera's last packets longer (docs/BENCHMARKS.md).
constexpr const char* kRecordLaunch =
    "( parsebin name=depay0 ! identity name=ticks silent=true ! mpegtsmux alignment=7 ! "
    "appsink name=sink sync=false async=false max-buffers=64 drop=true )";
constexpr const char* kRealm = "slapse";
constexpr const char* kSessionPrefix = "sessions/";

std::once_flag g_gst_once;

std::string SessionId(const std::string& session_name) {
  const std::string prefix = kSessionPrefix;
  return session_name.compare(0, prefix.size(), prefix) == 0 ? session_name.substr(prefix.size())
                                                             : session_name;
}

// Runs `fn` on the loop thread of `context` and waits for it. Not for use
// from the loop thread itself.
void RunInLoop(GMainContext* context, std::function<void()> fn) {
  struct Call {
    std::function<void()> fn;
    std::promise<void> done;
  };
  auto* call = new Call{std::move(fn), {}};
  std::future<void> done = call->done.get_future();
  g_main_context_invoke_full(
      context, G_PRIORITY_DEFAULT,
      [](gpointer p) -> gboolean {
        auto* c = static_cast<Call*>(p);
        c->fn();
        c->done.set_value();
        return G_SOURCE_REMOVE;
      },
      call, [](gpointer p) { delete static_cast<Call*>(p); });
  done.wait();
}

using MountPtr = std::shared_ptr<RtspPublishMount>;
MountPtr* NewMountRef(MountPtr m) { return new MountPtr(std::move(m)); }
void FreeMountRef(gpointer p) { delete static_cast<MountPtr*>(p); }

GstFlowReturn OnNewSample(GstAppSink* sink, gpointer data) {
  const MountPtr& mount = *static_cast<MountPtr*>(data);
  GstSample* sample = gst_app_sink_pull_sample(sink);
  if (sample == nullptr) return GST_FLOW_EOS;
  GstBuffer* buffer = gst_sample_get_buffer(sample);
  GstMapInfo map;
  Status written = Status::Ok();
  if (buffer != nullptr && gst_buffer_map(buffer, &map, GST_MAP_READ)) {
    // Blocks while the session's reader is behind (its buffer is full).
    written = mount->bytes()->Write(std::string(reinterpret_cast<const char*>(map.data), map.size),
                                    [] { return false; });
    gst_buffer_unmap(buffer, &map);
  }
  gst_sample_unref(sample);
  return written.ok() ? GST_FLOW_OK : GST_FLOW_EOS;
}

void OnEos(GstAppSink*, gpointer data) { (*static_cast<MountPtr*>(data))->PublisherGone(); }

// parsebin plugs the depayloader the SDP's caps ask for, then the parser,
// and stops at the parser's output (parsed=true), which mpegtsmux takes:
// left to itself parsebin looks for a further element there and fails
// ("missing parser" for MPEG-2 video).
gboolean ContinueUntilParsed(GstElement*, GstPad*, GstCaps* caps, gpointer) {
  const GstStructure* s = gst_caps_get_structure(caps, 0);
  gboolean parsed = FALSE;
  return s == nullptr || !gst_structure_get_boolean(s, "parsed", &parsed) || !parsed;
}

// A time in ns that MPEG-TS' 90 kHz clock holds exactly: the nearest tick,
// rounded up in ns. RTP's 90 kHz timestamps reach here truncated to ns
// (3000 ticks -> 33333333 ns) and mpegtsmux truncates them again (-> 2999
// ticks); rounded first, every frame keeps its RTP timestamp exactly.
GstClockTime OnTick(GstClockTime t) {
  if (!GST_CLOCK_TIME_IS_VALID(t)) return t;
  const guint64 ticks = gst_util_uint64_scale_round(t, 90000, GST_SECOND);
  return gst_util_uint64_scale_ceil(ticks, GST_SECOND, 90000);
}

GstPadProbeReturn RoundToTicks(GstPad*, GstPadProbeInfo* info, gpointer) {
  GstBuffer* buffer = gst_buffer_make_writable(gst_pad_probe_info_get_buffer(info));
  GST_BUFFER_PTS(buffer) = OnTick(GST_BUFFER_PTS(buffer));
  GST_BUFFER_DTS(buffer) = OnTick(GST_BUFFER_DTS(buffer));
  GST_PAD_PROBE_INFO_DATA(info) = buffer;
  return GST_PAD_PROBE_OK;
}

bool IsFrom(GstElement* element, const char* factory_name) {
  GstElementFactory* factory = gst_element_get_factory(element);
  return factory != nullptr && g_strcmp0(GST_OBJECT_NAME(factory), factory_name) == 0;
}

// Each RTP session of the media's rtpbin, as it is made: the RTCP it would
// send the publisher (receiver reports) is dropped; the publisher's own RTCP
// is still read. A publisher reads nothing it did not ask for once it stops
// sending, and closing a TCP socket that holds unread bytes aborts the
// connection (RST) and throws away what the publisher had queued but not yet
// sent: ffmpeg sends its TEARDOWN without waiting for the answer and closes
// at once, so a receiver report that arrived in that last moment cost the
// TEARDOWN (and the last frame, still in the parser): "lost without a
// TEARDOWN" after all but one frame (docs/BENCHMARKS.md).
GstPadProbeReturn DropBuffers(GstPad*, GstPadProbeInfo*, gpointer) { return GST_PAD_PROBE_DROP; }

void OnRtpSessionPadAdded(GstElement*, GstPad* pad, gpointer) {
  if (g_strcmp0(GST_PAD_NAME(pad), "send_rtcp_src") != 0) return;
  gst_pad_add_probe(pad,
                    GstPadProbeType(GST_PAD_PROBE_TYPE_BUFFER | GST_PAD_PROBE_TYPE_BUFFER_LIST),
                    &DropBuffers, nullptr, nullptr);
}

void OnDeepElementAdded(GstBin*, GstBin*, GstElement* element, gpointer) {
  if (IsFrom(element, "rtpsession")) {
    g_signal_connect(element, "pad-added", G_CALLBACK(OnRtpSessionPadAdded), nullptr);
  }
}

// The media's rtpbin, as it is added to the pipeline: timestamps from the
// RTP timestamps alone (buffer-mode "none"). The default ("slave") smooths
// them toward arrival times, which shifts every frame's stream time (3 s of
// video read as 2.7 s), so a drive published live would not equal its
// offline run.
void OnElementAdded(GstBin*, GstElement* element, gpointer) {
  if (IsFrom(element, "rtpbin")) gst_util_set_object_arg(G_OBJECT(element), "buffer-mode", "none");
}

void OnUnprepared(GstRTSPMedia*, gpointer data) {
  (*static_cast<MountPtr*>(data))->PublisherGone();
}

}  // namespace

RtspPublishMount::RtspPublishMount(int64_t buffer_bytes) {
  UploadQueueOptions o;
  o.capacity_bytes = buffer_bytes;
  bytes_ = std::make_shared<UploadQueue>(o);
  bytes_->Start();
}

void RtspPublishMount::PublisherGone() {
  End none = End::kNone;
  end_.compare_exchange_strong(none, teardown_ ? End::kTeardown : End::kLost);
  bytes_->Finish();
}

// ---------------------------------------------------------------------------

struct RtspIngest::Impl {
  struct Entry {
    std::string mount_path;  // "/sessions/<id>/<path>"
    std::string user;
    MountPtr mount;
    GstRTSPClient* publisher = nullptr;  // the first to ANNOUNCE here (a ref)
  };
  // What a factory's media-configure handler needs.
  struct FactoryRef {
    Impl* impl;
    std::string session_name;
  };

  RtspIngestOptions options;
  GMainContext* context = nullptr;
  GMainLoop* loop = nullptr;
  GstRTSPServer* server = nullptr;
  GstRTSPMountPoints* mounts = nullptr;
  GstRTSPAuth* auth = nullptr;
  GstRTSPAddressPool* udp_pool = nullptr;  // options.rtp_ports; null = any port
  std::thread thread;
  std::mutex mu;
  std::map<std::string, Entry> by_session;  // session name -> its mount

  // The entry whose mount path is `path` or a prefix of it ("/a/b" for
  // "/a/b/stream=0"); null if none. Under mu.
  Entry* EntryForPathLocked(const char* path) {
    if (path == nullptr) return nullptr;
    const std::string p = path;
    for (auto& [name, e] : by_session) {
      if (p == e.mount_path ||
          (p.size() > e.mount_path.size() && p.compare(0, e.mount_path.size(), e.mount_path) == 0 &&
           p[e.mount_path.size()] == '/')) {
        return &e;
      }
    }
    return nullptr;
  }

  std::string Password(const std::string& session_name) const {
    unsigned char mac[EVP_MAX_MD_SIZE];
    unsigned int len = 0;
    HMAC(EVP_sha256(), options.key.data(), static_cast<int>(options.key.size()),
         reinterpret_cast<const unsigned char*>(session_name.data()), session_name.size(), mac,
         &len);
    static constexpr char kHex[] = "0123456789abcdef";
    std::string out;
    for (unsigned int i = 0; i < 16 && i < len; ++i) {
      out += kHex[mac[i] >> 4];
      out += kHex[mac[i] & 15];
    }
    return out;
  }

  static void ReleasePublisher(Entry* e) {
    if (e->publisher != nullptr) g_object_unref(e->publisher);
    e->publisher = nullptr;
  }

  // Signal handlers; all run on the loop thread.
  static void OnClientConnected(GstRTSPServer*, GstRTSPClient* client, gpointer data);
  static GstRTSPStatusCode OnPreAnnounce(GstRTSPClient* client, GstRTSPContext* ctx, gpointer data);
  static void OnTeardown(GstRTSPClient* client, GstRTSPContext* ctx, gpointer data);
  static void OnClientClosed(GstRTSPClient* client, gpointer data);
  static void OnMediaConfigure(GstRTSPMediaFactory*, GstRTSPMedia* media, gpointer data);
};

void RtspIngest::Impl::OnClientConnected(GstRTSPServer*, GstRTSPClient* client, gpointer data) {
  g_signal_connect(client, "pre-announce-request", G_CALLBACK(OnPreAnnounce), data);
  g_signal_connect(client, "teardown-request", G_CALLBACK(OnTeardown), data);
  g_signal_connect(client, "closed", G_CALLBACK(OnClientClosed), data);
}

// ANNOUNCE, once authenticated (gst-rtsp-server has built the media by
// then): the first client is the publisher; a path that has (or had) one
// refuses any other with 503.
GstRTSPStatusCode RtspIngest::Impl::OnPreAnnounce(GstRTSPClient* client, GstRTSPContext* ctx,
                                                  gpointer data) {
  auto* impl = static_cast<Impl*>(data);
  std::lock_guard<std::mutex> lock(impl->mu);
  Entry* e = impl->EntryForPathLocked(ctx->uri != nullptr ? ctx->uri->abspath : nullptr);
  if (e == nullptr) return GST_RTSP_STS_OK;  // the server answers 404
  if (e->publisher == nullptr && !e->mount->had_publisher()) {
    e->publisher = GST_RTSP_CLIENT(g_object_ref(client));
    e->mount->SetHadPublisher();
  }
  return e->publisher == client ? GST_RTSP_STS_OK : GST_RTSP_STS_SERVICE_UNAVAILABLE;
}

void RtspIngest::Impl::OnTeardown(GstRTSPClient* client, GstRTSPContext* ctx, gpointer data) {
  auto* impl = static_cast<Impl*>(data);
  std::lock_guard<std::mutex> lock(impl->mu);
  Entry* e = impl->EntryForPathLocked(ctx->uri != nullptr ? ctx->uri->abspath : nullptr);
  if (e != nullptr && e->publisher == client) e->mount->SawTeardown();
}

// The publisher's connection closed. After a TEARDOWN the pipeline's EOS
// (eos-shutdown) ends the byte stream once the last frames are through
// (OnEos, OnUnprepared); without one the camera is lost, and the stream
// ends now (the frames still in the pipeline are not waited for).
void RtspIngest::Impl::OnClientClosed(GstRTSPClient* client, gpointer data) {
  auto* impl = static_cast<Impl*>(data);
  std::lock_guard<std::mutex> lock(impl->mu);
  for (auto& [name, e] : impl->by_session) {
    if (e.publisher != client) continue;
    if (!e.mount->saw_teardown()) e.mount->PublisherGone();
    ReleasePublisher(&e);
  }
}

// A publisher's media was built (it passed authentication): the first one
// claims the mount and feeds the session.
void RtspIngest::Impl::OnMediaConfigure(GstRTSPMediaFactory*, GstRTSPMedia* media, gpointer data) {
  auto* ref = static_cast<FactoryRef*>(data);
  MountPtr mount;
  {
    std::lock_guard<std::mutex> lock(ref->impl->mu);
    auto it = ref->impl->by_session.find(ref->session_name);
    if (it == ref->impl->by_session.end()) return;
    mount = it->second.mount;
  }
  GstElement* bin = gst_rtsp_media_get_element(media);
  GstObject* pipeline = gst_object_get_parent(GST_OBJECT(bin));
  if (pipeline != nullptr) {
    g_signal_connect(pipeline, "element-added", G_CALLBACK(OnElementAdded), nullptr);
    g_signal_connect(pipeline, "deep-element-added", G_CALLBACK(OnDeepElementAdded), nullptr);
    gst_object_unref(pipeline);
  }
  GstElement* ticks = gst_bin_get_by_name(GST_BIN(bin), "ticks");
  if (ticks != nullptr) {
    GstPad* src = gst_element_get_static_pad(ticks, "src");
    gst_pad_add_probe(src, GST_PAD_PROBE_TYPE_BUFFER, &RoundToTicks, nullptr, nullptr);
    gst_object_unref(src);
    gst_object_unref(ticks);
  }
  GstElement* depay = gst_bin_get_by_name(GST_BIN(bin), "depay0");
  if (depay != nullptr) {
    g_signal_connect(depay, "autoplug-continue", G_CALLBACK(ContinueUntilParsed), nullptr);
    gst_object_unref(depay);
  }
  if (!mount->Claim()) {  // a second publisher (refused at ANNOUNCE): bytes go nowhere
    gst_object_unref(bin);
    return;
  }
  GstElement* sink = gst_bin_get_by_name(GST_BIN(bin), "sink");
  if (sink != nullptr) {
    GstAppSinkCallbacks callbacks{};
    callbacks.eos = &OnEos;
    callbacks.new_sample = &OnNewSample;
    gst_app_sink_set_callbacks(GST_APP_SINK(sink), &callbacks, NewMountRef(mount), &FreeMountRef);
    gst_object_unref(sink);
  }
  gst_object_unref(bin);
  g_signal_connect_data(
      media, "unprepared", G_CALLBACK(OnUnprepared), NewMountRef(mount),
      [](gpointer p, GClosure*) { FreeMountRef(p); }, GConnectFlags(0));
}

// ---------------------------------------------------------------------------

namespace {
std::mutex g_registry_mu;
std::map<std::string, RtspIngest*> g_owner;  // session name -> the server it is mounted on
}  // namespace

RtspIngest::RtspIngest(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

StatusOr<std::unique_ptr<RtspIngest>> RtspIngest::Start(const RtspIngestOptions& options) {
  if (options.port < 0 || options.port > 65535) {
    return InvalidArgumentError("rtsp port must be in [0, 65535], got " +
                                std::to_string(options.port));
  }
  if (options.key.size() < 16) return InvalidArgumentError("the RTSP ingest key is too short");
  const std::string& url_host = options.url_host;
  if (url_host.size() > 253 ||
      url_host.find_first_not_of(
          "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.-") !=
          std::string::npos ||
      (!url_host.empty() && (url_host.front() == '-' || url_host.front() == '.'))) {
    return InvalidArgumentError(
        "the RTSP ingest URL host must be a DNS name or an IPv4 address (letters, digits, '.', "
        "'-'; serve --rtsp-url-host), got '" +
        url_host + "'");
  }
  const UdpPortRange& udp = options.rtp_ports;
  if (!udp.any() && !(udp.min_port > 0 && udp.min_port < udp.max_port && udp.max_port <= 65535)) {
    return InvalidArgumentError("RTP port range " + udp.ToString() + " is not a port range");
  }
  std::call_once(g_gst_once, [] { gst_init(nullptr, nullptr); });
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->context = g_main_context_new();
  impl->loop = g_main_loop_new(impl->context, FALSE);
  impl->server = gst_rtsp_server_new();
  gst_rtsp_server_set_address(impl->server, options.host.c_str());
  gst_rtsp_server_set_service(impl->server, std::to_string(options.port).c_str());
  impl->mounts = gst_rtsp_server_get_mount_points(impl->server);
  impl->auth = gst_rtsp_auth_new();
  gst_rtsp_auth_set_supported_methods(impl->auth, GST_RTSP_AUTH_DIGEST);
  gst_rtsp_auth_set_realm(impl->auth, kRealm);
  gst_rtsp_server_set_auth(impl->server, impl->auth);
  if (!udp.any()) {
    // Unicast ranges (ttl 0) on the wildcard addresses: a UDP publisher's
    // server ports are taken from them (one even RTP + RTCP pair each; a
    // pair another program holds is skipped), released with its media.
    impl->udp_pool = gst_rtsp_address_pool_new();
    for (const char* any : {GST_RTSP_ADDRESS_POOL_ANY_IPV4, GST_RTSP_ADDRESS_POOL_ANY_IPV6}) {
      gst_rtsp_address_pool_add_range(impl->udp_pool, any, any, udp.min_port, udp.max_port, 0);
    }
  }
  g_signal_connect(impl->server, "client-connected", G_CALLBACK(Impl::OnClientConnected),
                   impl.get());
  std::unique_ptr<RtspIngest> ingest(new RtspIngest(std::move(impl)));
  Impl* im = ingest->impl_.get();
  GError* error = nullptr;
  GSource* source = gst_rtsp_server_create_source(im->server, nullptr, &error);
  if (source == nullptr) {
    std::string why = error != nullptr ? error->message : "unknown error";
    if (error != nullptr) g_error_free(error);
    return UnavailableError("cannot listen for RTSP publishers on " + options.host + ":" +
                            std::to_string(options.port) + " (" + why +
                            "); choose another port with serve --rtsp-port");
  }
  g_source_attach(source, im->context);
  g_source_unref(source);
  ingest->port_ = gst_rtsp_server_get_bound_port(im->server);
  im->thread = std::thread([im] {
    g_main_context_push_thread_default(im->context);
    g_main_loop_run(im->loop);
    g_main_context_pop_thread_default(im->context);
  });
  return ingest;
}

RtspIngest::~RtspIngest() {
  std::vector<std::string> own;
  {
    std::lock_guard<std::mutex> lock(g_registry_mu);
    for (auto it = g_owner.begin(); it != g_owner.end();) {
      if (it->second == this) {
        own.push_back(it->first);
        it = g_owner.erase(it);
      } else {
        ++it;
      }
    }
  }
  for (const std::string& name : own) UnmountOwn(name);
  Impl* im = impl_.get();
  if (im->thread.joinable()) {  // else Start failed before the loop ran
    // Every remaining connection (failed publishers, idle clients) closes.
    RunInLoop(im->context, [im] {
      gst_rtsp_server_client_filter(
          im->server,
          [](GstRTSPServer*, GstRTSPClient*, gpointer) { return GST_RTSP_FILTER_REMOVE; }, nullptr);
    });
    g_main_loop_quit(im->loop);
    im->thread.join();
  }
  {
    std::lock_guard<std::mutex> lock(im->mu);
    for (auto& [name, e] : im->by_session) Impl::ReleasePublisher(&e);
  }
  g_object_unref(im->auth);
  if (im->udp_pool != nullptr) g_object_unref(im->udp_pool);
  g_object_unref(im->mounts);
  g_object_unref(im->server);
  g_main_loop_unref(im->loop);
  g_main_context_unref(im->context);
}

StatusOr<std::string> RtspIngest::Mount(const std::string& session_name, const std::string& path) {
  const std::string id = SessionId(session_name);
  const std::string mount_path = "/" + std::string(kSessionPrefix) + id + "/" + path;
  const RtspIngestOptions& o = impl_->options;
  const std::string url = "rtsp://" + (o.url_host.empty() ? o.host : o.url_host) + ":" +
                          std::to_string(port_) + mount_path;
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    if (impl_->by_session.count(session_name) > 0) return url;
    Impl::Entry e;
    e.mount_path = mount_path;
    e.user = id;
    e.mount = std::make_shared<RtspPublishMount>(impl_->options.buffer_bytes);
    impl_->by_session[session_name] = std::move(e);
  }
  GstRTSPMediaFactory* factory = gst_rtsp_media_factory_new();
  gst_rtsp_media_factory_set_launch(factory, kRecordLaunch);
  gst_rtsp_media_factory_set_transport_mode(factory, GST_RTSP_TRANSPORT_MODE_RECORD);
  gst_rtsp_media_factory_set_shared(factory, FALSE);
  if (impl_->udp_pool != nullptr) gst_rtsp_media_factory_set_address_pool(factory, impl_->udp_pool);
  // Unpreparing sends EOS first, so the muxer flushes the last frames.
  gst_rtsp_media_factory_set_eos_shutdown(factory, TRUE);
  // The role names a GstStructure: it must start with a letter.
  const std::string role = "publisher-" + id;
  gst_rtsp_media_factory_add_role(factory, role.c_str(), GST_RTSP_PERM_MEDIA_FACTORY_ACCESS,
                                  G_TYPE_BOOLEAN, TRUE, GST_RTSP_PERM_MEDIA_FACTORY_CONSTRUCT,
                                  G_TYPE_BOOLEAN, TRUE, nullptr);
  g_signal_connect_data(
      factory, "media-configure", G_CALLBACK(Impl::OnMediaConfigure),
      new Impl::FactoryRef{impl_.get(), session_name},
      [](gpointer p, GClosure*) { delete static_cast<Impl::FactoryRef*>(p); }, GConnectFlags(0));
  GstRTSPToken* token =
      gst_rtsp_token_new(GST_RTSP_TOKEN_MEDIA_FACTORY_ROLE, G_TYPE_STRING, role.c_str(), nullptr);
  gst_rtsp_auth_add_digest(impl_->auth, id.c_str(), impl_->Password(session_name).c_str(), token);
  gst_rtsp_token_unref(token);
  gst_rtsp_mount_points_add_factory(impl_->mounts, mount_path.c_str(), factory);
  {
    std::lock_guard<std::mutex> lock(g_registry_mu);
    g_owner[session_name] = this;
  }
  return url;
}

RtspPublishCredentials RtspIngest::Credentials(const std::string& session_name) const {
  return {SessionId(session_name), impl_->Password(session_name)};
}

std::shared_ptr<RtspPublishMount> RtspIngest::FindMount(const std::string& session_name) {
  std::lock_guard<std::mutex> lock(g_registry_mu);
  auto owner = g_owner.find(session_name);
  if (owner == g_owner.end()) return nullptr;
  Impl* im = owner->second->impl_.get();
  std::lock_guard<std::mutex> lock2(im->mu);
  auto it = im->by_session.find(session_name);
  return it == im->by_session.end() ? nullptr : it->second.mount;
}

void RtspIngest::Unmount(const std::string& session_name) {
  std::lock_guard<std::mutex> lock(g_registry_mu);
  auto owner = g_owner.find(session_name);
  if (owner == g_owner.end()) return;
  owner->second->UnmountOwn(session_name);
  g_owner.erase(owner);
}

void RtspIngest::UnmountOwn(const std::string& session_name) {
  Impl* im = impl_.get();
  RunInLoop(im->context, [im, &session_name] {
    Impl::Entry e;
    {
      std::lock_guard<std::mutex> lock(im->mu);
      auto it = im->by_session.find(session_name);
      if (it == im->by_session.end()) return;
      e = std::move(it->second);
      im->by_session.erase(it);
    }
    gst_rtsp_mount_points_remove_factory(im->mounts, e.mount_path.c_str());
    gst_rtsp_auth_remove_digest(im->auth, e.user.c_str());
    e.mount->bytes()->Close(CancelledError("the session's RTSP mount was removed"));
    // A publisher that sent TEARDOWN is left to gst-rtsp-server, which is
    // still answering it: the session ends as soon as the stream has
    // drained, and closing the connection then could cut that 200 OK off
    // (the publisher would report a failed TEARDOWN; seen under CPU load).
    // It closes its connection itself. Any other publisher is disconnected.
    if (e.publisher != nullptr && !e.mount->saw_teardown()) gst_rtsp_client_close(e.publisher);
    Impl::ReleasePublisher(&e);
  });
}

// ---------------------------------------------------------------------------

StatusOr<std::string> LoadOrCreateRtspIngestKey(const std::string& data_dir) {
  std::string key(32, '\0');
  if (data_dir == kInMemoryDataDir) {
    if (RAND_bytes(reinterpret_cast<unsigned char*>(key.data()), 32) != 1) {
      return InternalError("no random bytes for the RTSP ingest key");
    }
    return key;
  }
  const std::string path = data_dir + "/rtsp_ingest.key";
  std::ifstream in(path, std::ios::binary);
  if (in) {
    std::stringstream ss;
    ss << in.rdbuf();
    if (ss.str().size() < 32) {
      return FailedPreconditionError(path + " is shorter than 32 bytes; delete it to make a new " +
                                     "key (every RTSP push session then has new credentials)");
    }
    return ss.str();
  }
  if (RAND_bytes(reinterpret_cast<unsigned char*>(key.data()), 32) != 1) {
    return InternalError("no random bytes for the RTSP ingest key");
  }
  const int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0 || write(fd, key.data(), key.size()) != static_cast<ssize_t>(key.size())) {
    const std::string why = std::strerror(errno);
    if (fd >= 0) close(fd);
    return FailedPreconditionError("cannot write the RTSP ingest key " + path + ": " + why);
  }
  close(fd);
  return key;
}

std::string RtspPublishUrl(const std::string& ingest_url, const RtspPublishCredentials& c) {
  const std::string scheme = "rtsp://";
  if (c.username.empty() || ingest_url.compare(0, scheme.size(), scheme) != 0) return ingest_url;
  return scheme + c.username + ":" + c.password + "@" + ingest_url.substr(scheme.size());
}

}  // namespace slapse::server
