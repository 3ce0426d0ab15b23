// hermctl's text for people (apps/hermctl/format.hpp).

#include "apps/hermctl/format.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <ostream>
#include <sstream>

#include "routing/module_id.hpp"

namespace hermctl {

std::string text(const json& v) {
  if (v.is_null())
    return "-";
  if (v.is_string())
    return v.get<std::string>();
  if (v.is_boolean())
    return v.get<bool>() ? "yes" : "no";
  return v.dump();
}

std::string text(const json& obj, const char* key) {
  auto i = obj.find(key);
  return i == obj.end() ? "-" : text(*i);
}

std::string cost_text(const json& v) {
  return v.is_null() ? "inf" : text(v);
}

std::string number(double x) {
  std::ostringstream out;
  out << x;
  return out.str();
}

std::string bandwidth_text(uint64_t bps) {
  if (bps >= 1'000'000'000 && bps % 100'000'000 == 0)
    return number(double(bps) / 1e9) + " Gbit/s";
  if (bps >= 1'000'000)
    return number(double(bps) / 1e6) + " Mbit/s";
  if (bps >= 1'000)
    return number(double(bps) / 1e3) + " kbit/s";
  return std::to_string(bps) + " bit/s";
}

std::string duration_text(uint64_t ms) {
  auto s = ms / 1000;
  std::ostringstream out;
  if (s >= 86400)
    out << s / 86400 << "d ";
  if (s >= 3600)
    out << (s % 86400) / 3600 << "h ";
  if (s >= 60)
    out << (s % 3600) / 60 << "m ";
  out << s % 60 << "s";
  return out.str();
}

void print_table(std::ostream& out, const row& header,
                 const std::vector<row>& rows) {
  std::vector<size_t> width(header.size(), 0);
  auto measure = [&](const row& cells) {
    for (size_t i = 0; i < cells.size() && i < width.size(); ++i)
      width[i] = std::max(width[i], cells[i].size());
  };
  measure(header);
  for (auto& r : rows)
    measure(r);
  auto print = [&](const row& cells) {
    std::string line;
    for (size_t i = 0; i < cells.size() && i < width.size(); ++i) {
      line += cells[i];
      if (i + 1 < cells.size())
        line += std::string(width[i] - cells[i].size() + 2, ' ');
    }
    out << line << '\n';
  };
  print(header);
  for (auto& r : rows)
    print(r);
}

void print_pairs(std::ostream& out,
                 const std::vector<std::pair<std::string, std::string>>& pairs,
                 const std::string& indent) {
  size_t w = 0;
  for (auto& kv : pairs)
    w = std::max(w, kv.first.size());
  for (auto& kv : pairs)
    out << indent << kv.first << std::string(w - kv.first.size() + 2, ' ')
        << kv.second << '\n';
}

void print_json(std::ostream& out, const json& j) {
  out << j.dump(2, ' ', false, json::error_handler_t::replace) << '\n';
}

uint32_t mid_number(const json& v) {
  if (!v.is_string())
    return 0x10000;
  auto id = herm::parse_module_id(v.get<std::string>());
  return id ? *id : 0x10000;
}

std::string dot_escape(const std::string& s) {
  std::string out;
  for (char ch : s) {
    if (ch == '"' || ch == '\\')
      out += '\\';
    if (ch == '\n')
      continue;
    out += ch;
  }
  return out;
}

std::optional<uint64_t> parse_bandwidth(const std::string& s) {
  size_t used = 0;
  double x = 0;
  try {
    x = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  auto unit = s.substr(used);
  for (auto suffix : {"bit/s", "bps", "bit", "b/s"})
    if (unit.size() >= std::strlen(suffix)
        && unit.compare(unit.size() - std::strlen(suffix), std::string::npos,
                        suffix)
             == 0) {
      unit.resize(unit.size() - std::strlen(suffix));
      break;
    }
  double scale = 0;
  if (unit.empty())
    scale = 1;
  else if (unit == "k" || unit == "K")
    scale = 1e3;
  else if (unit == "M")
    scale = 1e6;
  else if (unit == "G")
    scale = 1e9;
  if (used == 0 || scale == 0 || !(x > 0) || x * scale > 1e15)
    return std::nullopt;
  return static_cast<uint64_t>(std::llround(x * scale));
}

} // namespace hermctl
