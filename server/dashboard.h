// The web dashboard (issue 16): static pages embedded in the binary (web/,
// see web/embed.cmake) and a JSON API over the same SessionManager the gRPC
// service uses, mounted on the server's HTTP port next to /metrics.
//
//   GET  /                       the fleet page (index.html); the login form
//                                (login.html) when tokens are on and the
//                                request carries none
//   GET  /session.html?name=...  one session's page
//   GET  /<asset>                the pages' modules and style (code only, no data)
//   POST /login                  form `token`: checks it, sets the HttpOnly,
//                                SameSite=Strict cookie `slapse_token`, 303 to /
//   POST /logout                 clears the cookie
//   GET  /api/sessions?filter=&order_by=&state=&page_size=&page_token=
//                                ListSessionsResponse (SessionManager::List,
//                                api/list_query.h: the gRPC ListSessions' query)
//   GET  /api/session?name=      Session
//   GET  /api/trajectory?name=&page_size=&page_token=&start_time_s=&end_time_s=
//                                Trajectory, a page as the store serves it
//   GET  /api/planes?name=&page_size=&page_token=      PlaneMap
//   POST /api/stop?name=         Session (StopSession)
//   POST /api/delete?name=       {} (DeleteSession)
//   GET  /api/download?name=&format=tum|kitti|json
//                                the trajectory as `slapse export` writes it
//                                (core/pipeline/result_io.h)
//   GET  /api/events?name=&after=   server-sent events: the session's event log
//                                (WatchSession's), one SessionEvent per event,
//                                `id:` = its sequence; a reconnecting browser's
//                                Last-Event-ID (or `after`) is the cursor, so
//                                nothing is lost or repeated. `event: end` when
//                                the log has ended.
//   GET  /api/overlay?name=&kind=mv|planes&max_width_px=
//                                image/png: the newest anchor frame's motion
//                                vectors, or the latest pair's planes, over
//                                its picture (server/frame_overlays.h; frames
//                                are kept only while someone asks: 503 until
//                                the next anchor); X-Slapse-Frame: its index,
//                                X-Slapse-Count: the vectors / planes drawn
//
// JSON is protobuf's JSON mapping of the v1 messages (proto field names,
// defaults printed; int64 as strings); an error is an ErrorStatus
// {"code": google.rpc.Code, "message": ...} with the matching HTTP status.
// Access is the gRPC API's: with tokens configured every /api route needs the
// caller's token (Authorization: Bearer, or the login cookie), another
// tenant's session is 404 as an unknown one, read-only tokens may not stop or
// delete; every Session and event is redacted (api/validate.h) first.
#pragma once

#include <cstddef>
#include <string>

#include "server/auth.h"
#include "server/http_server.h"
#include "server/session_manager.h"

namespace slapse::server {

// One file of web/, embedded at build time (web_assets.cc, generated).
struct WebAsset {
  const char* path;          // relative to web/, e.g. "index.html"
  const char* content_type;  // from the extension
  const unsigned char* data;
  size_t size;
};
extern const WebAsset kWebAssets[];
extern const size_t kWebAssetCount;

// Adds the dashboard's routes (above) to `http`. `sessions` and `auth` must
// outlive the HTTP server's serving (Stop() it first).
void MountDashboard(HttpServer* http, SessionManager* sessions, Authenticator* auth);

}  // namespace slapse::server
