#pragma once

// A recording of topics (hermctl record and play): one SQLite database,
// the schema of rosbag2's SQLite storage with HERM's additions (the
// publishing module and its sequence number, and the type descriptions
// known at recording time). docs/user-guide.md, "Record files", documents
// the schema; a file is readable with the sqlite3 tool.
//
// Not thread-safe; one bag per thread. Errors are thrown as bag_error with
// the file name and SQLite's message.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

struct sqlite3;

namespace hermctl {

struct bag_error : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// One recorded message.
struct bag_message {
  std::string topic;
  std::string type;
  /// Receive time at the recording module, ns since the epoch.
  int64_t time_ns = 0;
  uint64_t publisher = 0;
  uint32_t seq = 0;
  std::vector<uint8_t> payload;
};

/// Per topic: its type and how many messages.
struct bag_topic {
  std::string name;
  std::string type;
  uint64_t count = 0;
};

struct bag_info {
  std::string path;
  uint64_t size_bytes = 0;
  uint64_t messages = 0;
  int64_t start_ns = 0;
  int64_t end_ns = 0;
  std::vector<bag_topic> topics;
  /// Type name to its description (JSON text), as recorded.
  std::map<std::string, std::string> descriptions;
  /// The metadata table: recording module, hermctl version, ...
  std::map<std::string, std::string> metadata;
};

class bag {
public:
  /// Creates `path` for writing (refuses an existing file) or opens it for
  /// reading.
  static bag create(const std::string& path);
  static bag open(const std::string& path);

  bag(bag&&) noexcept;
  bag& operator=(bag&&) noexcept;
  ~bag();

  /// Writing, inside one transaction committed every `batch` messages and
  /// by flush() (a recording cut short keeps what was flushed).
  void add(const bag_message& m);
  void describe(const std::string& type, const std::string& json);
  void set_metadata(const std::string& key, const std::string& value);
  void flush();

  /// Reading: the summary, and every message in time order (of `only` the
  /// topics listed, all when empty); `f` returns false to stop.
  bag_info info();
  void read(const std::vector<std::string>& only,
            const std::function<bool(const bag_message&)>& f);

private:
  explicit bag(std::string path, sqlite3* db);
  void exec(const char* sql);
  int64_t topic_id(const std::string& topic, const std::string& type);
  [[noreturn]] void fail(const std::string& what);

  std::string path_;
  sqlite3* db_ = nullptr;
  std::map<std::pair<std::string, std::string>, int64_t> topic_ids_;
  size_t in_transaction_ = 0;
};

} // namespace hermctl
