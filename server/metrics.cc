#include "server/metrics.h"

#include <prometheus/histogram.h>
#include <prometheus/text_serializer.h>

#include <array>
#include <map>
#include <mutex>

#include "core/common/status.h"
#include "slapse/v1/slapse.grpc.pb.h"

namespace slapse::server {
namespace {

using prometheus::ClientMetric;
using prometheus::MetricFamily;
using prometheus::MetricType;

// The process's stage histograms: one registry shared by every server in the
// process (a session runner does not know its server).
struct StageHistograms {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  std::array<prometheus::Histogram*, 3> by_stage{};

  StageHistograms() {
    auto& family = prometheus::BuildHistogram()
                       .Name("slapse_stage_seconds")
                       .Help(
                           "Time per frame in each stage of a session: read (waiting for and "
                           "decoding the next frame), pipeline (the pipeline step), publish "
                           "(snapshots and events)")
                       .Register(*registry);
    // 50 us .. 2.5 s: a 320x240 frame's step is ~0.1-10 ms, a network wait up to seconds.
    const prometheus::Histogram::BucketBoundaries bounds = {0.00005, 0.0001, 0.00025, 0.0005, 0.001,
                                                            0.0025,  0.005,  0.01,    0.025,  0.05,
                                                            0.1,     0.25,   0.5,     1.0,    2.5};
    by_stage[static_cast<int>(Stage::kRead)] = &family.Add({{"stage", "read"}}, bounds);
    by_stage[static_cast<int>(Stage::kPipeline)] = &family.Add({{"stage", "pipeline"}}, bounds);
    by_stage[static_cast<int>(Stage::kPublish)] = &family.Add({{"stage", "publish"}}, bounds);
  }
};

StageHistograms& Stages() {
  static StageHistograms* stages = new StageHistograms();  // never destroyed: used at exit
  return *stages;
}

MetricFamily Family(const std::string& name, const std::string& help, MetricType type) {
  MetricFamily f;
  f.name = name;
  f.help = help;
  f.type = type;
  return f;
}

void AddSample(MetricFamily* f, std::vector<ClientMetric::Label> labels, double value) {
  ClientMetric m;
  m.label = std::move(labels);
  if (f->type == MetricType::Counter) {
    m.counter.value = value;
  } else {
    m.gauge.value = value;
  }
  f->metric.push_back(std::move(m));
}

// Every session the manager holds, all pages.
std::vector<v1::Session> AllSessions(const SessionManager& manager) {
  std::vector<v1::Session> all;
  v1::ListSessionsRequest request;
  request.set_page_size(1000);
  for (;;) {
    auto page = manager.List(request);
    if (!page.ok()) break;
    for (auto& s : *page->mutable_sessions()) all.push_back(std::move(s));
    if (page->next_page_token().empty()) break;
    request.set_page_token(page->next_page_token());
  }
  return all;
}

// The families read from the sessions' snapshots.
std::vector<MetricFamily> SessionFamilies(const std::vector<v1::Session>& sessions) {
  MetricFamily by_state = Family("slapse_sessions", "Sessions held, by state", MetricType::Gauge);
  std::map<int, int> state_count;
  for (int s = v1::Session::CREATED; s <= v1::Session::STOPPED; ++s) state_count[s] = 0;
  MetricFamily failed =
      Family("slapse_sessions_failed", "FAILED sessions held, by their error's gRPC status code",
             MetricType::Gauge);
  std::map<std::string, int> failed_by_code;
  constexpr int kPerSession = 8;  // the families below, one sample per session each
  std::vector<MetricFamily> per(kPerSession);
  per[0] = Family("slapse_session_frames_total", "Frames decoded", MetricType::Counter);
  per[1] = Family("slapse_session_anchor_pairs_total",
                  "Anchor pairs processed (one pose update each)", MetricType::Counter);
  per[2] =
      Family("slapse_session_tracked_pairs_total",
             "Anchor pairs on which the filter was tracking (tracked poses)", MetricType::Counter);
  per[3] = Family("slapse_session_reconnects_total", "RTSP pull reconnect attempts",
                  MetricType::Counter);
  per[4] = Family("slapse_session_planes", "Planes in the session's map", MetricType::Gauge);
  per[5] =
      Family("slapse_session_fps", "Frames processed per second of wall time", MetricType::Gauge);
  per[6] = Family("slapse_session_lag_seconds",
                  "Wall time since the first frame minus the stream time of the last frame",
                  MetricType::Gauge);
  per[7] = Family("slapse_session_plane_steps_total",
                  "Tracked anchor pairs whose step length a plane observation measured",
                  MetricType::Counter);
  for (const v1::Session& s : sessions) {
    ++state_count[s.state()];
    if (s.state() == v1::Session::FAILED) {
      ++failed_by_code[StatusCodeName(static_cast<StatusCode>(s.error().code()))];
    }
    const std::vector<ClientMetric::Label> l = {{"session", s.name()}};
    const v1::SessionStats& st = s.stats();
    const double values[kPerSession] = {static_cast<double>(st.frames()),
                                        static_cast<double>(st.anchor_pairs()),
                                        static_cast<double>(st.tracked_pairs()),
                                        static_cast<double>(st.reconnects()),
                                        static_cast<double>(st.planes()),
                                        st.fps(),
                                        st.lag_ms() / 1e3,
                                        static_cast<double>(st.plane_steps())};
    for (int i = 0; i < kPerSession; ++i) AddSample(&per[i], l, values[i]);
  }
  for (const auto& [state, n] : state_count) {
    AddSample(&by_state, {{"state", v1::Session::State_Name(state)}}, n);
  }
  for (const auto& [code, n] : failed_by_code) AddSample(&failed, {{"code", code}}, n);
  std::vector<MetricFamily> out = {std::move(by_state), std::move(failed)};
  for (auto& f : per) out.push_back(std::move(f));
  return out;
}

// Counts one call: RpcStarted when the call starts, RpcFinished just before
// its status is sent (so a client that has the status sees it counted), or
// with CANCELLED when the call ends without sending one.
class RpcMetricsInterceptor : public grpc::experimental::Interceptor {
 public:
  RpcMetricsInterceptor(ServerMetrics* metrics, std::string method)
      : metrics_(metrics), method_(std::move(method)) {
    metrics_->RpcStarted(method_);
  }
  ~RpcMetricsInterceptor() override {
    if (!finished_) metrics_->RpcFinished(method_, grpc::StatusCode::CANCELLED);
  }
  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (!finished_ && methods->QueryInterceptionHookPoint(
                          grpc::experimental::InterceptionHookPoints::PRE_SEND_STATUS)) {
      finished_ = true;
      metrics_->RpcFinished(method_, methods->GetSendStatus().error_code());
    }
    methods->Proceed();
  }

 private:
  ServerMetrics* metrics_;
  std::string method_;
  bool finished_ = false;
};

class RpcMetricsInterceptorFactory : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit RpcMetricsInterceptorFactory(ServerMetrics* metrics) : metrics_(metrics) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    return new RpcMetricsInterceptor(metrics_, info->method() ? info->method() : "");
  }

 private:
  ServerMetrics* metrics_;
};

}  // namespace

void StageTimer::Done() {
  if (done_) return;
  done_ = true;
  Stages().by_stage[static_cast<int>(stage_)]->Observe(
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
}

struct ServerMetrics::RpcFamilies {
  prometheus::Family<prometheus::Counter>* calls = nullptr;
  prometheus::Family<prometheus::Gauge>* in_flight = nullptr;
  prometheus::Gauge* watchers = nullptr;
  std::mutex mu;  // guards the maps (Family::Add is thread-safe, the caches are not)
  std::map<std::pair<std::string, int>, prometheus::Counter*> call_counters;
  std::map<std::string, prometheus::Gauge*> in_flight_gauges;
};

ServerMetrics::ServerMetrics(const SessionManager* sessions)
    : sessions_(sessions),
      registry_(std::make_shared<prometheus::Registry>()),
      rpc_(std::make_unique<RpcFamilies>()) {
  rpc_->calls = &prometheus::BuildCounter()
                     .Name("slapse_rpcs_total")
                     .Help("gRPC calls finished, by method and status code (code != OK: errors)")
                     .Register(*registry_);
  rpc_->in_flight = &prometheus::BuildGauge()
                         .Name("slapse_rpcs_in_flight")
                         .Help("gRPC calls in progress, by method")
                         .Register(*registry_);
  rpc_->watchers = &prometheus::BuildGauge()
                        .Name("slapse_watchers")
                        .Help("Open WatchSession streams")
                        .Register(*registry_)
                        .Add({});
}

ServerMetrics::~ServerMetrics() = default;

std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>>
ServerMetrics::InterceptorFactories() {
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> out;
  out.push_back(std::make_unique<RpcMetricsInterceptorFactory>(this));
  return out;
}

namespace {

bool IsWatch(const std::string& method) {
  static const std::string watch =
      "/" + std::string(v1::SlapseService::service_full_name()) + "/WatchSession";
  return method == watch;
}

}  // namespace

void ServerMetrics::RpcStarted(const std::string& method) {
  std::lock_guard<std::mutex> lock(rpc_->mu);
  auto& gauge = rpc_->in_flight_gauges[method];
  if (gauge == nullptr) gauge = &rpc_->in_flight->Add({{"method", method}});
  gauge->Increment();
  if (IsWatch(method)) rpc_->watchers->Increment();
}

void ServerMetrics::RpcFinished(const std::string& method, int grpc_code) {
  std::lock_guard<std::mutex> lock(rpc_->mu);
  rpc_->in_flight_gauges[method]->Decrement();
  if (IsWatch(method)) rpc_->watchers->Decrement();
  auto& counter = rpc_->call_counters[{method, grpc_code}];
  if (counter == nullptr) {
    counter = &rpc_->calls->Add(
        {{"method", method}, {"code", StatusCodeName(static_cast<StatusCode>(grpc_code))}});
  }
  counter->Increment();
}

std::string ServerMetrics::Exposition() const {
  std::vector<MetricFamily> families = SessionFamilies(AllSessions(*sessions_));
  MetricFamily store = Family("slapse_store_bytes",
                              "Bytes of data in the session store: SQLite pages in use, "
                              "(page_count - freelist_count) * page_size; the measure of "
                              "serve --retention-max-store-mb",
                              MetricType::Gauge);
  AddSample(&store, {}, static_cast<double>(sessions_->StoreBytes()));
  families.push_back(std::move(store));
  for (auto& f : registry_->Collect()) families.push_back(std::move(f));
  for (auto& f : Stages().registry->Collect()) families.push_back(std::move(f));
  return prometheus::TextSerializer().Serialize(families);
}

}  // namespace slapse::server
