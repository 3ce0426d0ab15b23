#include "apps/hermctl/watch.hpp"

#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <ostream>
#include <set>
#include <sstream>
#include <thread>
#include <tuple>
#include <utility>

namespace hermctl {

namespace {

constexpr const char* reverse_on = "\x1b[7m";
constexpr const char* reverse_off = "\x1b[0m";
constexpr const char* home = "\x1b[H";
constexpr const char* clear_line_rest = "\x1b[K";
constexpr const char* clear_screen_rest = "\x1b[J";

/// Names looked up per frame at most, so that a network full of new
/// modules does not stall a frame.
constexpr size_t names_per_frame = 8;

/// Frames after which a module that did not tell its name is asked again.
constexpr uint64_t name_retry_frames = 5;

/// Publishers listed per topic; the rest are counted.
constexpr size_t listed_publishers = 4;

uint64_t field(const json& obj, const char* key) {
  auto it = obj.find(key);
  if (it == obj.end() || !it->is_number_integer())
    return 0;
  return it->is_number_unsigned() || it->get<int64_t>() >= 0 ? it->get<uint64_t>() : 0;
}

std::string str(const json& obj, const char* key, const std::string& fallback) {
  auto it = obj.find(key);
  return it != obj.end() && it->is_string() ? it->get<std::string>() : fallback;
}

std::string cost_of(const std::optional<uint64_t>& c) {
  return c ? std::to_string(*c) : "inf";
}

/// `line` cut to `width` columns (UTF-8 continuation bytes take none).
std::string clip(const std::string& line, size_t width) {
  if (width == 0)
    return line;
  size_t cols = 0;
  for (size_t i = 0; i < line.size(); ++i) {
    if ((static_cast<unsigned char>(line[i]) & 0xC0) == 0x80)
      continue;
    if (++cols > width)
      return line.substr(0, i);
  }
  return line;
}

/// A frame under construction: lines, each maybe highlighted.
class canvas {
public:
  explicit canvas(const frame_style& s) : style_(s) {
  }

  void line(const std::string& text, bool highlight = false) {
    lines_.push_back({text, highlight});
  }

  /// A table; row i is highlighted when marks[i].
  void table(const row& header, const std::vector<row>& rows,
             const std::vector<bool>& marks = {}) {
    std::ostringstream t;
    print_table(t, header, rows);
    std::istringstream lines{t.str()};
    std::string l;
    for (size_t i = 0; std::getline(lines, l); ++i)
      line(l, i > 0 && i - 1 < marks.size() && marks[i - 1]);
  }

  /// The frame as text; on a terminal of `height` rows, the lines past
  /// height - 1 are replaced by one that counts them.
  std::string finish() {
    auto n = lines_.size();
    if (style_.ansi && style_.height > 1 && n > style_.height - 1) {
      auto cut = n - (style_.height - 2);
      lines_.resize(style_.height - 2);
      lines_.push_back({"... " + std::to_string(cut)
                          + " more lines: a taller terminal shows them",
                        true});
    }
    std::ostringstream out;
    if (style_.ansi)
      out << home;
    for (auto& [text, highlight] : lines_) {
      auto t = clip(text, style_.width);
      if (style_.ansi && highlight)
        out << reverse_on << t << reverse_off;
      else
        out << t;
      if (style_.ansi)
        out << clear_line_rest;
      out << '\n';
    }
    if (style_.ansi)
      out << clear_screen_rest;
    else
      out << '\n';
    return out.str();
  }

private:
  const frame_style& style_;
  std::vector<std::pair<std::string, bool>> lines_;
};

std::string rate(const watch_channel* before, const watch_channel& now,
                 uint64_t watch_channel::*counter, double seconds, bool bytes) {
  if (before == nullptr || !before->has_stats || !now.has_stats || seconds <= 0
      || now.*counter < before->*counter)
    return "-";
  auto per_s = static_cast<double>(now.*counter - before->*counter) / seconds;
  if (bytes)
    return byte_rate_text(per_s);
  char buf[32];
  std::snprintf(buf, sizeof(buf), per_s < 100 ? "%.1f" : "%.0f", per_s);
  return buf;
}

std::string name_of(const watch_snapshot& s, herm::module_id id) {
  auto it = s.names.find(id);
  return it == s.names.end() || it->second.empty() ? "-" : it->second;
}

/// What changed in the route to one destination, "" for nothing.
std::string route_change(const watch_route* before, const watch_route* now) {
  if (before == nullptr)
    return "new: cost " + cost_of(now->cost) + " via " + now->via + ", "
           + std::to_string(now->hops) + (now->hops == 1 ? " hop" : " hops");
  if (now == nullptr)
    return "gone (was cost " + cost_of(before->cost) + " via " + before->via + ")";
  std::string parts;
  auto add = [&parts](const std::string& p) {
    parts += (parts.empty() ? "" : ", ") + p;
  };
  if (before->cost != now->cost)
    add("cost " + cost_of(before->cost) + " -> " + cost_of(now->cost));
  if (before->via != now->via)
    add("via " + before->via + " -> " + now->via);
  if (before->hops != now->hops)
    add("hops " + std::to_string(before->hops) + " -> " + std::to_string(now->hops));
  return parts;
}

std::string more(size_t n) {
  return "... " + std::to_string(n) + " more";
}

} // namespace

// -- parsing --------------------------------------------------------------------

std::vector<watch_route> parse_routes(const json& routes) {
  std::vector<watch_route> out;
  if (!routes.is_array())
    return out;
  for (auto& r : routes) {
    if (!r.is_object() || !r.value("selected", false) || field(r, "size_class") != 0)
      continue;
    auto dest = mid_number(r.value("destination", json{}));
    if (dest > 0xFFFF)
      continue;
    watch_route w;
    w.destination = static_cast<herm::module_id>(dest);
    if (auto c = r.find("cost"); c != r.end() && c->is_number_integer())
      w.cost = field(r, "cost");
    w.hops = field(r, "hops");
    w.via = str(r, "neighbour_module", "-");
    out.push_back(std::move(w));
  }
  std::sort(out.begin(), out.end(), [](const watch_route& a, const watch_route& b) {
    return a.destination < b.destination;
  });
  out.erase(std::unique(out.begin(), out.end(),
                        [](const watch_route& a, const watch_route& b) {
                          return a.destination == b.destination;
                        }),
            out.end());
  if (out.size() > max_watch_rows)
    out.resize(max_watch_rows);
  return out;
}

std::vector<watch_channel> parse_channels(const json& channels) {
  std::vector<watch_channel> out;
  if (!channels.is_array())
    return out;
  for (auto& c : channels) {
    if (!c.is_object())
      continue;
    watch_channel w;
    w.id = field(c, "id");
    w.device = str(c, "device", "-");
    w.kind = str(c, "kind", "-");
    w.state = str(c, "state", "-");
    auto s = c.find("stats");
    if (s != c.end() && s->is_object()) {
      w.has_stats = true;
      w.tx_bytes = field(*s, "tx_bytes");
      w.rx_bytes = field(*s, "rx_bytes");
      w.tx_frames = field(*s, "tx_frames");
      w.rx_frames = field(*s, "rx_frames");
      w.drops = field(*s, "tx_dropped") + field(*s, "rx_malformed")
                + field(*s, "rx_reassembly_dropped") + field(*s, "rx_kernel_dropped")
                + field(*s, "rx_queue_dropped");
    }
    out.push_back(std::move(w));
  }
  std::sort(out.begin(), out.end(),
            [](const watch_channel& a, const watch_channel& b) { return a.id < b.id; });
  if (out.size() > max_watch_rows)
    out.resize(max_watch_rows);
  return out;
}

std::optional<std::vector<watch_topic>> parse_topics(const json& topics) {
  if (!topics.is_array())
    return std::nullopt;
  // Keeps at most listed_publishers names of a list; counts them all.
  auto names = [](const json& t, const char* key, std::vector<std::string>& kept) {
    auto i = t.find(key);
    if (i == t.end() || !i->is_array())
      return uint64_t{0};
    for (auto& m : *i)
      if (m.is_string() && kept.size() < listed_publishers)
        kept.push_back(m.get<std::string>());
    return static_cast<uint64_t>(i->size());
  };
  std::vector<watch_topic> out;
  for (auto& t : topics) {
    if (!t.is_object())
      continue;
    watch_topic w;
    w.topic = str(t, "topic", "-");
    w.type = str(t, "type", "");
    if (auto s = t.find("seqs"); s != t.end() && s->is_object())
      for (auto& [module, seq] : s->items())
        if (seq.is_number_unsigned() && w.seqs.size() < max_watch_rows)
          w.seqs[module] = seq.get<uint32_t>();
    w.publisher_count = names(t, "publishers", w.publishers);
    w.subscriber_count = names(t, "subscribers", w.subscribers);
    out.push_back(std::move(w));
  }
  std::sort(out.begin(), out.end(),
            [](const watch_topic& a, const watch_topic& b) { return a.topic < b.topic; });
  if (out.size() > max_watch_rows)
    out.resize(max_watch_rows);
  return out;
}

void carry_gone(const watch_snapshot& prev, watch_snapshot& cur) {
  std::set<std::string> devices;
  for (auto& c : cur.channels)
    devices.insert(c.device);
  for (auto& c : prev.channels) {
    if (cur.channels.size() >= max_watch_rows)
      break;
    if (devices.count(c.device) > 0)
      continue;
    watch_channel gone;
    gone.id = c.id;
    gone.device = c.device;
    gone.kind = c.kind;
    gone.state = "down";
    cur.channels.push_back(std::move(gone));
    devices.insert(c.device);
  }
  std::sort(cur.channels.begin(), cur.channels.end(),
            [](const watch_channel& a, const watch_channel& b) { return a.id < b.id; });
}

// -- rendering ------------------------------------------------------------------

std::string byte_rate_text(double bps) {
  static const char* units[] = {"B/s", "kB/s", "MB/s", "GB/s"};
  size_t u = 0;
  while (bps >= 999.5 && u + 1 < sizeof(units) / sizeof(units[0])) {
    bps /= 1000;
    ++u;
  }
  char buf[32];
  if (u == 0 || bps >= 9.95)
    std::snprintf(buf, sizeof(buf), "%.0f %s", bps, units[u]);
  else
    std::snprintf(buf, sizeof(buf), "%.1f %s", bps, units[u]);
  return buf;
}

std::string render_frame(const watch_snapshot* prev, const watch_snapshot& cur,
                         const frame_style& style) {
  canvas f{style};
  std::ostringstream head;
  head << (cur.name.empty() ? "-" : cur.name) << " (" << herm::to_hex(cur.self)
       << ")  frame " << style.number << ", every "
       << (style.interval_ms % 1000 == 0 ? duration_text(style.interval_ms)
                                         : std::to_string(style.interval_ms) + " ms");
  if (!style.clock.empty())
    head << ", " << style.clock;
  f.line(head.str());
  for (auto& e : cur.errors)
    f.line("error: " + e, true);

  // Route changes, by destination, old and new routes merged.
  std::map<herm::module_id, std::string> changes;
  if (prev != nullptr) {
    std::map<herm::module_id, std::pair<const watch_route*, const watch_route*>> both;
    for (auto& r : prev->routes)
      both[r.destination].first = &r;
    for (auto& r : cur.routes)
      both[r.destination].second = &r;
    for (auto& [dest, pair] : both)
      if (auto c = route_change(pair.first, pair.second); !c.empty())
        changes[dest] = c;
  }

  // Modules: the watched one, then each destination.
  f.line("");
  f.line("modules (" + std::to_string(cur.routes.size() + 1) + ")");
  std::vector<row> rows{{herm::to_hex(cur.self), cur.name.empty() ? "-" : cur.name,
                         "0", "0", "-"}};
  std::vector<bool> marks{false};
  for (auto& r : cur.routes) {
    if (rows.size() >= max_watch_rows)
      break;
    rows.push_back({herm::to_hex(r.destination), name_of(cur, r.destination),
                    cost_of(r.cost), std::to_string(r.hops), r.via});
    marks.push_back(changes.count(r.destination) > 0);
  }
  f.table({"MODULE", "NAME", "COST", "HOPS", "VIA"}, rows, marks);
  if (cur.routes.size() + 1 > rows.size())
    f.line(more(cur.routes.size() + 1 - rows.size()));

  // Links with rates over the time since the previous snapshot.
  f.line("");
  f.line("links (" + std::to_string(cur.channels.size()) + ")");
  double seconds = prev != nullptr && cur.at_ms > prev->at_ms
                     ? static_cast<double>(cur.at_ms - prev->at_ms) / 1000.0
                     : 0;
  rows.clear();
  marks.clear();
  std::map<std::pair<uint64_t, std::string>, const watch_channel*> earlier;
  if (prev != nullptr)
    for (auto& p : prev->channels)
      earlier[{p.id, p.device}] = &p;
  for (auto& c : cur.channels) {
    auto found = earlier.find({c.id, c.device});
    const watch_channel* before = found == earlier.end() ? nullptr : found->second;
    std::string drops = "-";
    if (c.has_stats) {
      drops = std::to_string(c.drops);
      if (before != nullptr && before->has_stats && c.drops > before->drops)
        drops += " (+" + std::to_string(c.drops - before->drops) + ")";
    }
    rows.push_back({c.device, std::to_string(c.id), c.kind, c.state,
                    rate(before, c, &watch_channel::tx_bytes, seconds, true),
                    rate(before, c, &watch_channel::rx_bytes, seconds, true),
                    rate(before, c, &watch_channel::tx_frames, seconds, false),
                    rate(before, c, &watch_channel::rx_frames, seconds, false),
                    drops});
    marks.push_back(c.state != "up"
                    || (before != nullptr && c.drops > before->drops));
  }
  if (rows.empty())
    f.line("(no channels)");
  else
    f.table({"DEVICE", "ID", "KIND", "STATE", "TX B/S", "RX B/S", "TX FR/S",
             "RX FR/S", "DROPS"},
            rows, marks);

  // Route changes since the previous frame.
  f.line("");
  f.line("route changes (" + std::to_string(changes.size()) + ")");
  size_t shown = 0;
  for (auto& [dest, text] : changes) {
    if (++shown > max_watch_rows) {
      f.line(more(changes.size() - max_watch_rows));
      break;
    }
    f.line(herm::to_hex(dest) + "  " + text, true);
  }
  if (changes.empty())
    f.line(prev == nullptr ? "(first frame)" : "(none)");

  // Topics of every module that answered: the rate each is published at
  // (the increase of its publishers' sequence numbers).
  f.line("");
  if (!cur.topics) {
    f.line("topics");
    f.line(cur.topics_note.empty() ? "(not available)" : cur.topics_note);
    return f.finish();
  }
  f.line("topics (" + std::to_string(cur.topics->size()) + ", from "
         + std::to_string(cur.topic_modules) + " modules)");
  if (!cur.topics_unanswered.empty()) {
    std::string list;
    for (auto& m : cur.topics_unanswered)
      list += (list.empty() ? "" : ",") + m;
    f.line("(no answer from " + list + ")", true);
  }
  rows.clear();
  std::map<std::string, const watch_topic*> before;
  if (prev != nullptr && prev->topics)
    for (auto& t : *prev->topics)
      before[t.topic] = &t;
  auto listed = [](const std::vector<std::string>& kept, uint64_t count) {
    std::string text;
    for (auto& m : kept)
      text += (text.empty() ? "" : ",") + m;
    if (count > kept.size())
      text += " +" + std::to_string(count - kept.size());
    return text.empty() ? std::string{"-"} : text;
  };
  for (auto& t : *cur.topics) {
    std::string pub_rate = "-";
    auto b = before.find(t.topic);
    if (b != before.end() && seconds > 0) {
      uint64_t published = 0;
      bool known = false;
      for (auto& [module, seq] : t.seqs)
        if (auto old = b->second->seqs.find(module); old != b->second->seqs.end()) {
          published += static_cast<uint32_t>(seq - old->second);
          known = true;
        }
      if (known) {
        char buf[32];
        auto per_s = static_cast<double>(published) / seconds;
        std::snprintf(buf, sizeof(buf), per_s < 100 ? "%.1f" : "%.0f", per_s);
        pub_rate = buf;
      }
    }
    rows.push_back({t.topic, t.type.empty() ? "-" : t.type, pub_rate,
                    listed(t.publishers, t.publisher_count),
                    listed(t.subscribers, t.subscriber_count)});
  }
  if (rows.empty())
    f.line("(none)");
  else
    f.table({"TOPIC", "TYPE", "PUB/S", "PUBLISHERS", "SUBSCRIBERS"}, rows);
  return f.finish();
}

// -- the loop -------------------------------------------------------------------

namespace {

/// The terminal's columns and rows; `fallback` columns and no row limit
/// when unknown.
std::pair<size_t, size_t> terminal_size(size_t fallback) {
  winsize ws{};
  if (::ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 0)
    return {ws.ws_col, ws.ws_row};
  return {fallback, 0};
}

std::string wall_clock() {
  auto t = std::time(nullptr);
  std::tm tm{};
  ::localtime_r(&t, &tm);
  char buf[16];
  std::strftime(buf, sizeof(buf), "%H:%M:%S", &tm);
  return buf;
}

uint64_t steady_ms() {
  return static_cast<uint64_t>(
    std::chrono::duration_cast<std::chrono::milliseconds>(
      std::chrono::steady_clock::now().time_since_epoch())
      .count());
}

/// A module's name, or when it was last asked in vain.
struct name_entry {
  std::string name;
  bool known = false;
  uint64_t asked_frame = 0;
};

/// One poll (frame `frame`); sections whose request failed keep `prev`'s
/// rows.
watch_snapshot poll(const control_fn& call, const watch_options& o,
                    const watch_snapshot* prev, uint64_t frame,
                    std::map<herm::module_id, name_entry>& names) {
  watch_snapshot s;
  s.at_ms = steady_ms();
  if (prev != nullptr) {
    s.self = prev->self;
    s.name = prev->name;
  }
  auto me = call({{"cmd", "echo"}}, o.module);
  if (me.ok) {
    s.self = static_cast<herm::module_id>(field(me.result, "id"));
    s.name = str(me.result, "name", "");
  } else {
    s.errors.push_back("echo: " + me.error);
  }
  auto routes = call({{"cmd", "routes"}, {"all", false}}, o.module);
  if (routes.ok)
    s.routes = parse_routes(routes.result);
  else {
    s.errors.push_back("routes: " + routes.error);
    if (prev != nullptr)
      s.routes = prev->routes;
  }
  auto channels = call({{"cmd", "channels"}}, o.module);
  if (channels.ok)
    s.channels = parse_channels(channels.result);
  else {
    s.errors.push_back("channels: " + channels.error);
    if (prev != nullptr)
      s.channels = prev->channels;
  }
  auto topics = call({{"cmd", "topics"}, {"all", true}}, o.module);
  if (topics.ok) {
    auto rows = topics.result.find("topics");  // end() if not an object
    s.topics = parse_topics(rows != topics.result.end() ? *rows : json{});
    s.topic_modules = field(topics.result, "modules");
    if (auto u = topics.result.find("unanswered"); u != topics.result.end() && u->is_array())
      for (auto& m : *u)
        if (m.is_string() && s.topics_unanswered.size() < listed_publishers)
          s.topics_unanswered.push_back(m.get<std::string>());
    if (!s.topics)
      s.topics_note = "(the module's \"topics\" reply is not a list)";
  } else {
    s.topics_note = "(not available from this module: " + topics.error + ")";
  }
  size_t asked = 0;
  for (auto& r : s.routes) {
    auto it = names.find(r.destination);
    if (it != names.end()
        && (it->second.known || frame < it->second.asked_frame + name_retry_frames))
      continue;
    if (it == names.end() && names.size() >= 4 * max_watch_rows)
      continue;
    if (asked++ == names_per_frame)
      break;
    auto echo = call({{"cmd", "echo"}}, r.destination);
    names[r.destination] = echo.ok ? name_entry{str(echo.result, "name", ""), true, frame}
                                   : name_entry{"", false, frame};
  }
  for (auto& r : s.routes)
    if (auto it = names.find(r.destination); it != names.end() && it->second.known)
      s.names[r.destination] = it->second.name;
  s.names[s.self] = s.name;
  return s;
}

} // namespace

void run_watch(const control_fn& call, const watch_options& o, std::ostream& out) {
  std::optional<watch_snapshot> prev;
  std::map<herm::module_id, name_entry> names;
  for (uint64_t n = 1; o.count == 0 || n <= o.count; ++n) {
    auto started = std::chrono::steady_clock::now();
    auto cur = poll(call, o, prev ? &*prev : nullptr, n, names);
    if (prev)
      carry_gone(*prev, cur);
    frame_style style;
    style.ansi = o.ansi;
    style.width = o.width;
    if (o.ansi)
      std::tie(style.width, style.height) = terminal_size(o.width);
    style.number = n;
    style.interval_ms = static_cast<uint64_t>(o.interval.count());
    style.clock = wall_clock();
    out << render_frame(prev ? &*prev : nullptr, cur, style) << std::flush;
    prev = std::move(cur);
    if (o.count != 0 && n == o.count)
      break;
    std::this_thread::sleep_until(started + o.interval);
  }
}

} // namespace hermctl
