#include "actors/type_description.hpp"

#include <atomic>
#include <mutex>
#include <unordered_map>

#include "actors/text_form.hpp"

namespace herm {

namespace {

/// Longest type name on the wire (docs/protocol.md, "Type names").
constexpr size_t max_name = 255;

struct registry {
  std::mutex mtx;
  std::map<std::string, type_description> local;
  std::map<std::string, type_description> learned;
  std::unordered_map<std::type_index, std::string> by_cpp_type;
  std::atomic<uint64_t> refused{0};
};

registry& reg() {
  static registry r;
  return r;
}

std::string check(const type_description& d) {
  if (d.name.empty() || d.name.size() > max_name)
    return "a type name has 1 to 255 bytes";
  for (auto& f : d.fields) {
    if (f.name.empty() || f.name.size() > max_name)
      return "field names have 1 to 255 bytes";
    if (auto why = check_field_type(f.type); !why.empty())
      return "field '" + f.name + "': " + why;
  }
  return {};
}

} // namespace

caf::error register_description(type_description d,
                                std::optional<std::type_index> cpp_type) {
  if (auto why = check(d); !why.empty())
    return make_error(ec::invalid_parameter,
                      "description of '" + d.name + "': " + why);
  auto& r = reg();
  std::lock_guard<std::mutex> guard{r.mtx};
  if (cpp_type)
    r.by_cpp_type[*cpp_type] = d.name;
  r.learned.erase(d.name);
  auto name = d.name;
  r.local[name] = std::move(d);
  return {};
}

bool learn_description(const type_description& d) {
  if (!check(d).empty())
    return false;
  auto& r = reg();
  std::lock_guard<std::mutex> guard{r.mtx};
  if (r.local.count(d.name) > 0)
    return true;
  auto i = r.learned.find(d.name);
  if (i != r.learned.end()) {
    i->second = d;
    return true;
  }
  if (r.learned.size() >= max_learned_descriptions) {
    ++r.refused;
    return false;
  }
  r.learned.emplace(d.name, d);
  return true;
}

std::optional<type_description> find_description(const std::string& name) {
  auto& r = reg();
  std::lock_guard<std::mutex> guard{r.mtx};
  if (auto i = r.local.find(name); i != r.local.end())
    return i->second;
  if (auto i = r.learned.find(name); i != r.learned.end())
    return i->second;
  return std::nullopt;
}

std::vector<type_description> local_descriptions() {
  auto& r = reg();
  std::lock_guard<std::mutex> guard{r.mtx};
  std::vector<type_description> out;
  for (auto& [name, d] : r.local)
    out.push_back(d);
  return out;
}

uint64_t learned_descriptions_refused() {
  return reg().refused.load();
}

namespace detail {

std::string described_name(std::type_index t) {
  auto& r = reg();
  std::lock_guard<std::mutex> guard{r.mtx};
  auto i = r.by_cpp_type.find(t);
  return i == r.by_cpp_type.end() ? std::string{} : i->second;
}

void register_described_name(std::type_index t, std::string name) {
  auto& r = reg();
  std::lock_guard<std::mutex> guard{r.mtx};
  r.by_cpp_type[t] = std::move(name);
}

std::vector<std::string> split_field_names(const char* names) {
  std::vector<std::string> out;
  std::string cur;
  for (auto* p = names; ; ++p) {
    if (*p == ',' || *p == '\0') {
      auto b = cur.find_first_not_of(" \t\n");
      auto e = cur.find_last_not_of(" \t\n");
      if (b != std::string::npos)
        out.push_back(cur.substr(b, e - b + 1));
      cur.clear();
      if (*p == '\0')
        break;
    } else {
      cur += *p;
    }
  }
  return out;
}

} // namespace detail

} // namespace herm
