#include "apps/hermctl/bag.hpp"

#include <sqlite3.h>

#include <algorithm>

#include <sys/stat.h>

namespace hermctl {

namespace {

/// Messages per transaction while recording.
constexpr size_t batch = 256;

/// The schema (docs/user-guide.md, "Record files"). `topics` and `messages`
/// follow rosbag2's SQLite storage; `serialization_format` is "herm-apo-1"
/// (docs/protocol.md, "APO payloads").
const char* schema = R"(
CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
INSERT INTO schema VALUES (1, 'herm');
CREATE TABLE metadata(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE topics(
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL,
  type TEXT NOT NULL,
  serialization_format TEXT NOT NULL,
  offered_qos_profiles TEXT NOT NULL,
  UNIQUE(name, type));
CREATE TABLE messages(
  id INTEGER PRIMARY KEY,
  topic_id INTEGER NOT NULL REFERENCES topics(id),
  timestamp INTEGER NOT NULL,
  publisher INTEGER NOT NULL,
  seq INTEGER NOT NULL,
  data BLOB NOT NULL);
CREATE INDEX timestamp_idx ON messages (timestamp ASC);
CREATE TABLE type_descriptions(name TEXT PRIMARY KEY, description TEXT NOT NULL);
)";

/// A prepared statement, finalized when it goes out of scope.
struct statement {
  sqlite3_stmt* s = nullptr;
  ~statement() {
    sqlite3_finalize(s);
  }
};

} // namespace

bag::bag(std::string path, sqlite3* db) : path_(std::move(path)), db_(db) {
}

bag::bag(bag&& other) noexcept
  : path_(std::move(other.path_)),
    db_(other.db_),
    topic_ids_(std::move(other.topic_ids_)),
    in_transaction_(other.in_transaction_) {
  other.db_ = nullptr;
}

bag& bag::operator=(bag&& other) noexcept {
  std::swap(path_, other.path_);
  std::swap(db_, other.db_);
  std::swap(topic_ids_, other.topic_ids_);
  std::swap(in_transaction_, other.in_transaction_);
  return *this;
}

bag::~bag() {
  if (db_ == nullptr)
    return;
  try {
    flush();
  } catch (const bag_error&) {
    // Nothing to tell anyone from a destructor; flush() is explicit.
  }
  sqlite3_close(db_);
}

void bag::fail(const std::string& what) {
  throw bag_error{path_ + ": " + what
                  + (db_ != nullptr ? std::string{": "} + sqlite3_errmsg(db_)
                                    : std::string{})};
}

void bag::exec(const char* sql) {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = err != nullptr ? err : "unknown error";
    sqlite3_free(err);
    throw bag_error{path_ + ": " + msg};
  }
}

bag bag::create(const std::string& path) {
  struct stat sb;
  if (::stat(path.c_str(), &sb) == 0)
    throw bag_error{path + ": exists already (record does not overwrite)"};
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db,
                      SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr)
      != SQLITE_OK) {
    std::string msg = db != nullptr ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    throw bag_error{path + ": cannot create: " + msg};
  }
  bag b{path, db};
  b.exec("PRAGMA journal_mode=WAL;");
  b.exec(schema);
  return b;
}

bag bag::open(const std::string& path) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr)
      != SQLITE_OK) {
    std::string msg = db != nullptr ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    throw bag_error{path + ": cannot open: " + msg};
  }
  bag b{path, db};
  statement st;
  if (sqlite3_prepare_v2(db, "SELECT ros_distro FROM schema", -1, &st.s,
                         nullptr)
        != SQLITE_OK
      || sqlite3_step(st.s) != SQLITE_ROW)
    throw bag_error{path + ": not a HERM recording (no schema table)"};
  return b;
}

int64_t bag::topic_id(const std::string& topic, const std::string& type) {
  auto key = std::make_pair(topic, type);
  if (auto i = topic_ids_.find(key); i != topic_ids_.end())
    return i->second;
  statement st;
  if (sqlite3_prepare_v2(db_,
                         "INSERT INTO topics(name, type, serialization_format, "
                         "offered_qos_profiles) VALUES (?, ?, 'herm-apo-1', '')",
                         -1, &st.s, nullptr)
      != SQLITE_OK)
    fail("cannot add topic '" + topic + "'");
  sqlite3_bind_text(st.s, 1, topic.c_str(), static_cast<int>(topic.size()),
                    SQLITE_TRANSIENT);
  sqlite3_bind_text(st.s, 2, type.c_str(), static_cast<int>(type.size()),
                    SQLITE_TRANSIENT);
  if (sqlite3_step(st.s) != SQLITE_DONE)
    fail("cannot add topic '" + topic + "'");
  auto id = sqlite3_last_insert_rowid(db_);
  topic_ids_.emplace(key, id);
  return id;
}

void bag::add(const bag_message& m) {
  if (in_transaction_ == 0)
    exec("BEGIN");
  auto tid = topic_id(m.topic, m.type);
  statement st;
  if (sqlite3_prepare_v2(db_,
                         "INSERT INTO messages(topic_id, timestamp, publisher, "
                         "seq, data) VALUES (?, ?, ?, ?, ?)",
                         -1, &st.s, nullptr)
      != SQLITE_OK)
    fail("cannot add a message");
  sqlite3_bind_int64(st.s, 1, tid);
  sqlite3_bind_int64(st.s, 2, m.time_ns);
  sqlite3_bind_int64(st.s, 3, static_cast<int64_t>(m.publisher));
  sqlite3_bind_int64(st.s, 4, m.seq);
  // An empty vector's data() may be null, which SQLite binds as NULL (the
  // column is NOT NULL): an empty message is an empty blob.
  if (m.payload.empty())
    sqlite3_bind_zeroblob(st.s, 5, 0);
  else
    sqlite3_bind_blob(st.s, 5, m.payload.data(),
                      static_cast<int>(m.payload.size()), SQLITE_TRANSIENT);
  if (sqlite3_step(st.s) != SQLITE_DONE)
    fail("cannot add a message");
  if (++in_transaction_ >= batch)
    flush();
}

void bag::describe(const std::string& type, const std::string& json) {
  statement st;
  if (sqlite3_prepare_v2(db_,
                         "INSERT OR REPLACE INTO type_descriptions VALUES (?, ?)",
                         -1, &st.s, nullptr)
      != SQLITE_OK)
    fail("cannot add a type description");
  sqlite3_bind_text(st.s, 1, type.c_str(), static_cast<int>(type.size()),
                    SQLITE_TRANSIENT);
  sqlite3_bind_text(st.s, 2, json.c_str(), static_cast<int>(json.size()),
                    SQLITE_TRANSIENT);
  if (sqlite3_step(st.s) != SQLITE_DONE)
    fail("cannot add a type description");
}

void bag::set_metadata(const std::string& key, const std::string& value) {
  statement st;
  if (sqlite3_prepare_v2(db_, "INSERT OR REPLACE INTO metadata VALUES (?, ?)",
                         -1, &st.s, nullptr)
      != SQLITE_OK)
    fail("cannot write metadata");
  sqlite3_bind_text(st.s, 1, key.c_str(), static_cast<int>(key.size()),
                    SQLITE_TRANSIENT);
  sqlite3_bind_text(st.s, 2, value.c_str(), static_cast<int>(value.size()),
                    SQLITE_TRANSIENT);
  if (sqlite3_step(st.s) != SQLITE_DONE)
    fail("cannot write metadata");
}

void bag::flush() {
  if (in_transaction_ == 0)
    return;
  in_transaction_ = 0;
  exec("COMMIT");
}

bag_info bag::info() {
  bag_info out;
  out.path = path_;
  struct stat sb;
  if (::stat(path_.c_str(), &sb) == 0)
    out.size_bytes = static_cast<uint64_t>(sb.st_size);
  auto text = [](sqlite3_stmt* s, int col) {
    auto p = sqlite3_column_text(s, col);
    return p != nullptr ? std::string{reinterpret_cast<const char*>(p)}
                        : std::string{};
  };
  {
    statement st;
    if (sqlite3_prepare_v2(db_,
                           "SELECT count(*), coalesce(min(timestamp), 0), "
                           "coalesce(max(timestamp), 0) FROM messages",
                           -1, &st.s, nullptr)
          != SQLITE_OK
        || sqlite3_step(st.s) != SQLITE_ROW)
      fail("cannot read the messages");
    out.messages = static_cast<uint64_t>(sqlite3_column_int64(st.s, 0));
    out.start_ns = sqlite3_column_int64(st.s, 1);
    out.end_ns = sqlite3_column_int64(st.s, 2);
  }
  {
    statement st;
    if (sqlite3_prepare_v2(db_,
                           "SELECT t.name, t.type, count(m.id) FROM topics t "
                           "LEFT JOIN messages m ON m.topic_id = t.id "
                           "GROUP BY t.id ORDER BY t.name, t.type",
                           -1, &st.s, nullptr)
        != SQLITE_OK)
      fail("cannot read the topics");
    while (sqlite3_step(st.s) == SQLITE_ROW)
      out.topics.push_back({text(st.s, 0), text(st.s, 1),
                            static_cast<uint64_t>(sqlite3_column_int64(st.s, 2))});
  }
  {
    statement st;
    if (sqlite3_prepare_v2(db_, "SELECT name, description FROM type_descriptions",
                           -1, &st.s, nullptr)
        != SQLITE_OK)
      fail("cannot read the type descriptions");
    while (sqlite3_step(st.s) == SQLITE_ROW)
      out.descriptions[text(st.s, 0)] = text(st.s, 1);
  }
  {
    statement st;
    if (sqlite3_prepare_v2(db_, "SELECT key, value FROM metadata", -1, &st.s,
                           nullptr)
        != SQLITE_OK)
      fail("cannot read the metadata");
    while (sqlite3_step(st.s) == SQLITE_ROW)
      out.metadata[text(st.s, 0)] = text(st.s, 1);
  }
  return out;
}

void bag::read(const std::vector<std::string>& only,
               const std::function<bool(const bag_message&)>& f) {
  statement st;
  if (sqlite3_prepare_v2(db_,
                         "SELECT t.name, t.type, m.timestamp, m.publisher, "
                         "m.seq, m.data FROM messages m JOIN topics t ON "
                         "m.topic_id = t.id ORDER BY m.timestamp, m.id",
                         -1, &st.s, nullptr)
      != SQLITE_OK)
    fail("cannot read the messages");
  for (;;) {
    auto rc = sqlite3_step(st.s);
    if (rc == SQLITE_DONE)
      return;
    if (rc != SQLITE_ROW)
      fail("cannot read the messages");
    bag_message m;
    m.topic = reinterpret_cast<const char*>(sqlite3_column_text(st.s, 0));
    if (!only.empty()
        && std::find(only.begin(), only.end(), m.topic) == only.end())
      continue;
    m.type = reinterpret_cast<const char*>(sqlite3_column_text(st.s, 1));
    m.time_ns = sqlite3_column_int64(st.s, 2);
    m.publisher = static_cast<uint64_t>(sqlite3_column_int64(st.s, 3));
    m.seq = static_cast<uint32_t>(sqlite3_column_int64(st.s, 4));
    auto* data = static_cast<const uint8_t*>(sqlite3_column_blob(st.s, 5));
    auto n = sqlite3_column_bytes(st.s, 5);
    if (data != nullptr && n > 0)
      m.payload.assign(data, data + n);
    if (!f(m))
      return;
  }
}

} // namespace hermctl
