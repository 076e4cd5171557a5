#include "api/list_query.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <utility>

#include "api/validate.h"

namespace slapse::api {
namespace {

using google::protobuf::FieldDescriptor;
using google::protobuf::util::TimeUtil;

constexpr char kFieldsHelp[] =
    "fields are name, codec, state, source, create_time, update_time, stats.<counter>, "
    "labels.<key>";

// ---- what a field is and how to read it from a session ----

enum class Field { kName, kCodec, kState, kSource, kCreateTime, kUpdateTime, kStats, kLabel };
enum class Kind { kText, kEnum, kTime, kNumber };

Kind KindOf(Field f) {
  switch (f) {
    case Field::kName:
    case Field::kCodec:
    case Field::kSource:
    case Field::kLabel:
      return Kind::kText;
    case Field::kState:
      return Kind::kEnum;
    case Field::kCreateTime:
    case Field::kUpdateTime:
      return Kind::kTime;
    case Field::kStats:
      return Kind::kNumber;
  }
  return Kind::kText;
}

// A numeric SessionStats field by name, or null.
const FieldDescriptor* StatsField(const std::string& name) {
  const FieldDescriptor* f = v1::SessionStats::descriptor()->FindFieldByName(name);
  if (f == nullptr || f->is_repeated()) return nullptr;
  switch (f->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32:
    case FieldDescriptor::CPPTYPE_INT64:
    case FieldDescriptor::CPPTYPE_UINT32:
    case FieldDescriptor::CPPTYPE_UINT64:
    case FieldDescriptor::CPPTYPE_DOUBLE:
    case FieldDescriptor::CPPTYPE_FLOAT:
      return f;
    default:
      return nullptr;
  }
}

std::string StatsCounters() {
  std::string out;
  const auto* d = v1::SessionStats::descriptor();
  for (int i = 0; i < d->field_count(); ++i) {
    if (StatsField(d->field(i)->name()) == nullptr) continue;
    out += (out.empty() ? "" : ", ") + d->field(i)->name();
  }
  return out;
}

double StatsValue(const v1::Session& s, const FieldDescriptor* f) {
  const auto* r = s.stats().GetReflection();
  switch (f->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32:
      return r->GetInt32(s.stats(), f);
    case FieldDescriptor::CPPTYPE_INT64:
      return static_cast<double>(r->GetInt64(s.stats(), f));
    case FieldDescriptor::CPPTYPE_UINT32:
      return r->GetUInt32(s.stats(), f);
    case FieldDescriptor::CPPTYPE_UINT64:
      return static_cast<double>(r->GetUInt64(s.stats(), f));
    case FieldDescriptor::CPPTYPE_FLOAT:
      return r->GetFloat(s.stats(), f);
    default:
      return r->GetDouble(s.stats(), f);
  }
}

// The source oneof's case as its field name ("upload", "rtsp_pull", ...),
// empty if unset.
std::string SourceName(const v1::Session& s) {
  const auto* oneof = v1::Session::descriptor()->FindOneofByName("source");
  const FieldDescriptor* f = s.GetReflection()->GetOneofFieldDescriptor(s, oneof);
  return f == nullptr ? "" : f->name();
}

std::string SourceNames() {
  std::string out;
  const auto* oneof = v1::Session::descriptor()->FindOneofByName("source");
  for (int i = 0; i < oneof->field_count(); ++i) {
    out += (i == 0 ? "" : ", ") + oneof->field(i)->name();
  }
  return out;
}

std::string StateNames() {
  std::string out;
  const auto* d = v1::Session::State_descriptor();
  for (int i = 0; i < d->value_count(); ++i) {
    if (d->value(i)->number() == v1::Session::STATE_UNSPECIFIED) continue;
    out += (out.empty() ? "" : ", ") + d->value(i)->name();
  }
  return out;
}

// A field path as written ("state", "stats.fps", "labels.site").
struct FieldRef {
  Field field = Field::kName;
  std::string key;                         // label key
  const FieldDescriptor* stats = nullptr;  // stats counter
};

Status ResolveField(const std::string& path, size_t column, FieldRef* out) {
  static const std::pair<const char*, Field> kPlain[] = {{"name", Field::kName},
                                                         {"codec", Field::kCodec},
                                                         {"state", Field::kState},
                                                         {"source", Field::kSource},
                                                         {"create_time", Field::kCreateTime},
                                                         {"update_time", Field::kUpdateTime}};
  for (const auto& [name, field] : kPlain) {
    if (path == name) {
      out->field = field;
      return Status::Ok();
    }
  }
  const std::string at = " at column " + std::to_string(column);
  if (path.rfind("stats.", 0) == 0) {
    out->field = Field::kStats;
    out->stats = StatsField(path.substr(6));
    if (out->stats == nullptr) {
      return InvalidArgumentError("unknown counter '" + path + "'" + at + "; counters are " +
                                  StatsCounters());
    }
    return Status::Ok();
  }
  if (path.rfind("labels.", 0) == 0 && path.size() > 7) {
    out->field = Field::kLabel;
    out->key = path.substr(7);
    return Status::Ok();
  }
  return InvalidArgumentError("unknown field '" + path + "'" + at + "; " + kFieldsHelp);
}

int64_t TimeNs(const google::protobuf::Timestamp& t) { return TimeUtil::TimestampToNanoseconds(t); }

// ---- lexer ----

enum class Tok { kEnd, kLParen, kRParen, kCompare, kWord, kString, kAnd, kOr, kNot, kMinus };

struct Token {
  Tok type = Tok::kEnd;
  std::string text;
  size_t column = 0;  // 1-based
};

bool IsWordChar(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '*' ||
         c == '+' || c == '-';
}

StatusOr<std::vector<Token>> Lex(const std::string& s) {
  std::vector<Token> out;
  size_t i = 0;
  while (i < s.size()) {
    const char c = s[i];
    const size_t col = i + 1;
    if (std::isspace(static_cast<unsigned char>(c))) {
      ++i;
    } else if (c == '(' || c == ')') {
      out.push_back({c == '(' ? Tok::kLParen : Tok::kRParen, std::string(1, c), col});
      ++i;
    } else if (c == '=' || c == ':') {
      out.push_back({Tok::kCompare, std::string(1, c), col});
      ++i;
    } else if (c == '!' || c == '<' || c == '>') {
      const bool eq = i + 1 < s.size() && s[i + 1] == '=';
      if (c == '!' && !eq)
        return InvalidArgumentError("'!' must be '!=' at column " + std::to_string(col));
      out.push_back({Tok::kCompare, s.substr(i, eq ? 2 : 1), col});
      i += eq ? 2 : 1;
    } else if (c == '"') {
      std::string text;
      ++i;
      while (i < s.size() && s[i] != '"') {
        if (s[i] == '\\' && i + 1 < s.size()) ++i;
        text += s[i++];
      }
      if (i == s.size()) {
        return InvalidArgumentError("unterminated string starting at column " +
                                    std::to_string(col));
      }
      ++i;
      out.push_back({Tok::kString, std::move(text), col});
    } else if (c == '-' && i + 1 < s.size() &&
               (std::isalpha(static_cast<unsigned char>(s[i + 1])) || s[i + 1] == '(')) {
      // "-state=FAILED" negates; "-3" is a number (a word).
      out.push_back({Tok::kMinus, "-", col});
      ++i;
    } else if (IsWordChar(c)) {
      size_t j = i;
      while (j < s.size() && IsWordChar(s[j])) ++j;
      std::string w = s.substr(i, j - i);
      Tok t = w == "AND" ? Tok::kAnd : w == "OR" ? Tok::kOr : w == "NOT" ? Tok::kNot : Tok::kWord;
      out.push_back({t, std::move(w), col});
      i = j;
    } else {
      return InvalidArgumentError(std::string("unexpected character '") + c + "' at column " +
                                  std::to_string(col));
    }
  }
  out.push_back({Tok::kEnd, "", s.size() + 1});
  return out;
}

}  // namespace

// ---- the parsed filter ----

struct SessionFilter::Node {
  enum class Op { kAnd, kOr, kNot, kCompare, kHasLabel };
  Op op = Op::kCompare;
  std::vector<std::shared_ptr<const Node>> children;
  FieldRef ref;
  std::string cmp;   // "=", "!=", "<", "<=", ">", ">=", ":"
  std::string text;  // text / enum / source value (with any '*')
  double number = 0;
  int64_t time_ns = 0;
  int state = 0;
};

namespace {

using Node = SessionFilter::Node;
using NodePtr = std::shared_ptr<const Node>;

bool WildcardMatch(const std::string& pattern, const std::string& value) {
  const bool lead = !pattern.empty() && pattern.front() == '*';
  const bool trail = pattern.size() > 1 && pattern.back() == '*';
  if (!lead && !trail) return pattern == value;
  const std::string core = pattern.substr(lead ? 1 : 0, pattern.size() - lead - trail);
  if (lead && trail) return value.find(core) != std::string::npos;
  if (lead) {
    return value.size() >= core.size() &&
           value.compare(value.size() - core.size(), core.size(), core) == 0;
  }
  return value.compare(0, core.size(), core) == 0;
}

template <typename T>
bool CompareOrdered(const std::string& cmp, T a, T b) {
  if (cmp == "=" || cmp == ":") return a == b;
  if (cmp == "!=") return a != b;
  if (cmp == "<") return a < b;
  if (cmp == "<=") return a <= b;
  if (cmp == ">") return a > b;
  return a >= b;
}

bool Eval(const Node& n, const v1::Session& s) {
  switch (n.op) {
    case Node::Op::kAnd:
      return std::all_of(n.children.begin(), n.children.end(),
                         [&](const NodePtr& c) { return Eval(*c, s); });
    case Node::Op::kOr:
      return std::any_of(n.children.begin(), n.children.end(),
                         [&](const NodePtr& c) { return Eval(*c, s); });
    case Node::Op::kNot:
      return !Eval(*n.children[0], s);
    case Node::Op::kHasLabel:
      return s.labels().count(n.ref.key) > 0;
    case Node::Op::kCompare:
      break;
  }
  std::string text;
  switch (n.ref.field) {
    case Field::kState:
      return CompareOrdered(n.cmp, static_cast<int>(s.state()), n.state);
    case Field::kCreateTime:
      return CompareOrdered(n.cmp, TimeNs(s.create_time()), n.time_ns);
    case Field::kUpdateTime:
      return CompareOrdered(n.cmp, TimeNs(s.update_time()), n.time_ns);
    case Field::kStats:
      return CompareOrdered(n.cmp, StatsValue(s, n.ref.stats), n.number);
    case Field::kName:
      text = s.name();
      break;
    case Field::kCodec:
      text = s.stream_report().codec();
      break;
    case Field::kSource:
      text = SourceName(s);
      break;
    case Field::kLabel: {
      auto it = s.labels().find(n.ref.key);
      if (it == s.labels().end()) return n.cmp == "!=";
      if (n.cmp == ":" && n.text == "*") return true;
      text = it->second;
      break;
    }
  }
  const bool match = WildcardMatch(n.text, text);
  return n.cmp == "!=" ? !match : match;
}

class Parser {
 public:
  explicit Parser(std::vector<Token> tokens) : t_(std::move(tokens)) {}

  StatusOr<NodePtr> ParseAll() {
    auto e = Expression(0);
    if (!e.ok()) return e.status();
    if (Peek().type != Tok::kEnd) return Unexpected("AND, OR or the end of the filter");
    return e;
  }

 private:
  const Token& Peek() const { return t_[pos_]; }
  const Token& Next() { return t_[pos_ < t_.size() - 1 ? pos_++ : pos_]; }

  Status Unexpected(const std::string& wanted) const {
    const Token& t = Peek();
    const std::string got = t.type == Tok::kEnd ? "the end of the filter" : "'" + t.text + "'";
    return InvalidArgumentError("expected " + wanted + " at column " + std::to_string(t.column) +
                                ", got " + got);
  }

  static NodePtr Join(Node::Op op, std::vector<NodePtr> children) {
    if (children.size() == 1) return children[0];
    auto n = std::make_shared<Node>();
    n->op = op;
    n->children = std::move(children);
    return n;
  }

  // expression := sequence { AND sequence }; sequence := factor { factor }
  StatusOr<NodePtr> Expression(int depth) {
    if (depth > kMaxFilterDepth) {
      return InvalidArgumentError("filter nests deeper than " + std::to_string(kMaxFilterDepth));
    }
    std::vector<NodePtr> all;
    while (true) {
      auto f = Factor(depth);
      if (!f.ok()) return f.status();
      all.push_back(*f);
      const Tok next = Peek().type;
      if (next == Tok::kAnd) {
        Next();
      } else if (next == Tok::kEnd || next == Tok::kRParen) {
        break;
      }  // else juxtaposition: another factor, ANDed
    }
    return Join(Node::Op::kAnd, std::move(all));
  }

  // factor := term { OR term }
  StatusOr<NodePtr> Factor(int depth) {
    std::vector<NodePtr> any;
    while (true) {
      auto t = Term(depth);
      if (!t.ok()) return t.status();
      any.push_back(*t);
      if (Peek().type != Tok::kOr) break;
      Next();
    }
    return Join(Node::Op::kOr, std::move(any));
  }

  // term := [NOT | -] simple; simple := ( expression ) | restriction
  StatusOr<NodePtr> Term(int depth) {
    if (Peek().type == Tok::kNot || Peek().type == Tok::kMinus) {
      Next();
      auto inner = Term(depth + 1);
      if (!inner.ok()) return inner.status();
      auto n = std::make_shared<Node>();
      n->op = Node::Op::kNot;
      n->children.push_back(*inner);
      return NodePtr(n);
    }
    if (Peek().type == Tok::kLParen) {
      Next();
      auto e = Expression(depth + 1);
      if (!e.ok()) return e.status();
      if (Peek().type != Tok::kRParen) return Unexpected("')'");
      Next();
      return e;
    }
    return Restriction();
  }

  StatusOr<std::string> Value() {
    std::string prefix;
    if (Peek().type == Tok::kMinus) prefix = Next().text;
    if (Peek().type != Tok::kWord && Peek().type != Tok::kString) return Unexpected("a value");
    return prefix + Next().text;
  }

  StatusOr<NodePtr> Restriction() {
    if (Peek().type != Tok::kWord) return Unexpected("a field (" + std::string(kFieldsHelp) + ")");
    const Token field = Next();
    if (Peek().type != Tok::kCompare) {
      return InvalidArgumentError("'" + field.text + "' at column " + std::to_string(field.column) +
                                  " needs a comparison, e.g. state=RUNNING or labels.site=depot");
    }
    const Token cmp = Next();
    auto value = Value();
    if (!value.ok()) return value.status();
    auto n = std::make_shared<Node>();
    if (field.text == "labels" && cmp.text == ":") {
      n->op = Node::Op::kHasLabel;
      n->ref.key = *value;
      return NodePtr(n);
    }
    SLAPSE_RETURN_IF_ERROR(ResolveField(field.text, field.column, &n->ref));
    n->cmp = cmp.text;
    n->text = *value;
    SLAPSE_RETURN_IF_ERROR(CheckValue(field, n.get()));
    return NodePtr(n);
  }

  // The comparison and the value suit the field's kind; fills the typed value.
  static Status CheckValue(const Token& field, Node* n) {
    const std::string where = "'" + field.text + "' at column " + std::to_string(field.column);
    const bool equality = n->cmp == "=" || n->cmp == "!=" || n->cmp == ":";
    switch (KindOf(n->ref.field)) {
      case Kind::kText:
        if (!equality) return InvalidArgumentError(where + " is text: use =, != or :");
        if (n->ref.field == Field::kSource && SourceNameIsUnknown(n->text)) {
          return InvalidArgumentError(where + ": unknown source '" + n->text + "'; one of " +
                                      SourceNames());
        }
        return Status::Ok();
      case Kind::kEnum: {
        v1::Session::State st;
        if (!equality) return InvalidArgumentError(where + " is a state: use = or !=");
        if (!v1::Session::State_Parse(n->text, &st) || st == v1::Session::STATE_UNSPECIFIED) {
          return InvalidArgumentError(where + ": unknown state '" + n->text + "'; one of " +
                                      StateNames());
        }
        n->state = st;
        return Status::Ok();
      }
      case Kind::kTime: {
        google::protobuf::Timestamp ts;
        if (!TimeUtil::FromString(n->text, &ts)) {
          return InvalidArgumentError(where + ": '" + n->text +
                                      "' is not an RFC 3339 time; quote it, e.g. " + field.text +
                                      " > \"2026-11-23T10:00:00Z\"");
        }
        n->time_ns = TimeNs(ts);
        return Status::Ok();
      }
      case Kind::kNumber: {
        char* end = nullptr;
        n->number = std::strtod(n->text.c_str(), &end);
        if (n->text.empty() || end == nullptr || *end != '\0') {
          return InvalidArgumentError(where + ": '" + n->text + "' is not a number");
        }
        return Status::Ok();
      }
    }
    return Status::Ok();
  }

  static bool SourceNameIsUnknown(const std::string& pattern) {
    if (pattern.find('*') != std::string::npos) return false;
    const auto* oneof = v1::Session::descriptor()->FindOneofByName("source");
    for (int i = 0; i < oneof->field_count(); ++i) {
      if (oneof->field(i)->name() == pattern) return false;
    }
    return true;
  }

  std::vector<Token> t_;
  size_t pos_ = 0;
};

}  // namespace

SessionFilter::SessionFilter() = default;

StatusOr<SessionFilter> SessionFilter::Parse(const std::string& expression) {
  if (expression.size() > kMaxListQueryChars) {
    return InvalidArgumentError("filter is longer than " + std::to_string(kMaxListQueryChars) +
                                " characters");
  }
  SessionFilter out;
  auto tokens = Lex(expression);
  if (!tokens.ok()) return Status(tokens.status().code(), "filter: " + tokens.status().message());
  if (tokens->size() == 1) return out;  // only the end: match all
  auto root = Parser(std::move(*tokens)).ParseAll();
  if (!root.ok()) return Status(root.status().code(), "filter: " + root.status().message());
  out.root_ = *root;
  return out;
}

bool SessionFilter::Matches(const v1::Session& session) const {
  return root_ == nullptr || Eval(*root_, session);
}

// ---- order ----

struct SessionOrder::Key {
  FieldRef ref;
  bool desc = false;
};

namespace {

// -1, 0 or 1 as `a` sorts before, with or after `b` by `ref` (ascending).
int CompareBy(const FieldRef& ref, const v1::Session& a, const v1::Session& b) {
  auto three = [](auto x, auto y) { return x < y ? -1 : (y < x ? 1 : 0); };
  switch (ref.field) {
    case Field::kName:
      return three(a.name(), b.name());
    case Field::kCodec:
      return three(a.stream_report().codec(), b.stream_report().codec());
    case Field::kSource:
      return three(SourceName(a), SourceName(b));
    case Field::kState:
      return three(static_cast<int>(a.state()), static_cast<int>(b.state()));
    case Field::kCreateTime:
      return three(TimeNs(a.create_time()), TimeNs(b.create_time()));
    case Field::kUpdateTime:
      return three(TimeNs(a.update_time()), TimeNs(b.update_time()));
    case Field::kStats:
      return three(StatsValue(a, ref.stats), StatsValue(b, ref.stats));
    case Field::kLabel: {
      // A session without the label sorts before one with it.
      auto ia = a.labels().find(ref.key);
      auto ib = b.labels().find(ref.key);
      const bool ha = ia != a.labels().end(), hb = ib != b.labels().end();
      if (ha != hb) return ha ? 1 : -1;
      return ha ? three(ia->second, ib->second) : 0;
    }
  }
  return 0;
}

}  // namespace

SessionOrder::SessionOrder() = default;

StatusOr<SessionOrder> SessionOrder::Parse(const std::string& order_by) {
  if (order_by.size() > kMaxListQueryChars) {
    return InvalidArgumentError("order_by is longer than " + std::to_string(kMaxListQueryChars) +
                                " characters");
  }
  SessionOrder out;
  size_t start = 0;
  while (start <= order_by.size()) {
    size_t comma = order_by.find(',', start);
    if (comma == std::string::npos) comma = order_by.size();
    const std::string item = order_by.substr(start, comma - start);
    std::vector<std::string> words;
    for (size_t i = 0; i < item.size();) {
      while (i < item.size() && std::isspace(static_cast<unsigned char>(item[i]))) ++i;
      size_t j = i;
      while (j < item.size() && !std::isspace(static_cast<unsigned char>(item[j]))) ++j;
      if (j > i) words.push_back(item.substr(i, j - i));
      i = j;
    }
    const std::string where = "order_by item " + std::to_string(out.keys_.size() + 1);
    if (words.empty()) {
      if (order_by.find_first_not_of(" \t") == std::string::npos) break;  // empty = default
      return InvalidArgumentError(where + " is empty; write \"field [asc|desc], ...\"");
    }
    if (words.size() > 2 || (words.size() == 2 && words[1] != "asc" && words[1] != "desc")) {
      return InvalidArgumentError(where + " '" + item + "': want \"field\", \"field asc\" or " +
                                  "\"field desc\"");
    }
    auto key = std::make_shared<Key>();
    key->desc = words.size() == 2 && words[1] == "desc";
    Status s = ResolveField(words[0], start + 1, &key->ref);
    if (!s.ok()) return Status(s.code(), "order_by: " + s.message());
    out.keys_.push_back(key);
    start = comma + 1;
  }
  return out;
}

bool SessionOrder::Less(const v1::Session& a, const v1::Session& b) const {
  for (const auto& key : keys_) {
    const int c = CompareBy(key->ref, a, b);
    if (c != 0) return key->desc ? c > 0 : c < 0;
  }
  // Ties keep the order the caller passed (ApplyListQuery sorts stably).
  return false;
}

// ---- the page ----

namespace {

// FNV-1a of the query a token belongs to, so a token is refused with another
// filter or order.
uint64_t QueryHash(const v1::ListSessionsRequest& r) {
  uint64_t h = 1469598103934665603ull;
  const std::string q =
      r.filter() + '\n' + r.order_by() + '\n' + std::to_string(static_cast<int>(r.state_filter()));
  for (unsigned char c : q) h = (h ^ c) * 1099511628211ull;
  return h;
}

std::string MakeToken(size_t offset, uint64_t hash) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%zu-%016llx", offset, static_cast<unsigned long long>(hash));
  return buf;
}

StatusOr<size_t> ReadToken(const std::string& token, uint64_t hash) {
  if (token.empty()) return size_t{0};
  size_t offset = 0;
  unsigned long long h = 0;
  int used = 0;
  if (std::sscanf(token.c_str(), "%zu-%16llx%n", &offset, &h, &used) != 2 ||
      used != static_cast<int>(token.size())) {
    return InvalidArgumentError("page_token is not one this server issued; start from an " +
                                std::string("empty page_token"));
  }
  if (h != hash) {
    return InvalidArgumentError(
        "page_token belongs to another filter, order_by or state_filter; send the same query "
        "as the first page, or start again from an empty page_token");
  }
  return offset;
}

}  // namespace

StatusOr<v1::ListSessionsResponse> ApplyListQuery(std::vector<v1::Session> sessions,
                                                  const v1::ListSessionsRequest& request) {
  SLAPSE_RETURN_IF_ERROR(ValidateListRequest(request));
  auto filter = SessionFilter::Parse(request.filter());
  if (!filter.ok()) return filter.status();
  auto order = SessionOrder::Parse(request.order_by());
  if (!order.ok()) return order.status();
  const uint64_t hash = QueryHash(request);
  auto offset = ReadToken(request.page_token(), hash);
  if (!offset.ok()) return offset.status();

  std::vector<v1::Session> kept;
  for (auto& s : sessions) {
    if (request.state_filter() != v1::Session::STATE_UNSPECIFIED &&
        s.state() != request.state_filter()) {
      continue;
    }
    if (filter->Matches(s)) kept.push_back(std::move(s));
  }
  std::stable_sort(kept.begin(), kept.end(),
                   [&](const v1::Session& a, const v1::Session& b) { return order->Less(a, b); });
  const size_t page_size = request.page_size() == 0
                               ? kDefaultListPageSize
                               : std::min(request.page_size(), kMaxListPageSize);
  v1::ListSessionsResponse out;
  for (size_t i = *offset; i < kept.size() && i < *offset + page_size; ++i) {
    *out.add_sessions() = std::move(kept[i]);
  }
  if (*offset + page_size < kept.size())
    out.set_next_page_token(MakeToken(*offset + page_size, hash));
  return out;
}

}  // namespace slapse::api
