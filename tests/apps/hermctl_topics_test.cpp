// hermctl's data verbs against real processes: two hermd modules and the
// calculator example (a program that embeds HERM and serves a control
// socket) in a line over UDP on loopback, calc 0x20 -- a 0x21 -- b 0x22.
// topic pub/echo/list/hz, call (built-in, described hermd and user types,
// errors), record, record --info and play into a fresh subscriber compared
// message for message. Every wait is bounded; nothing asserts on timing.

#include <gtest/gtest.h>

#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "channels/testing/loopback.hpp"
#include "tests/support/process.hpp"

using namespace herm::test;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace {

const std::string hermd = HERMD_BIN;
const std::string hermctl = HERMCTL_BIN;
const std::string calculator = HERM_CALCULATOR_BIN;

std::string lo(uint16_t port) {
  return "127.0.0.1:" + std::to_string(port);
}

std::vector<std::string> lines_of(const std::string& out) {
  std::vector<std::string> lines;
  std::istringstream in{out};
  for (std::string l; std::getline(in, l);)
    if (!l.empty())
      lines.push_back(l);
  return lines;
}

class hermctl_topics_test : public ::testing::Test {
protected:
  static void SetUpTestSuite() {
    char tmpl[] = "/tmp/herm-topics-XXXXXX";
    dir_ = ::mkdtemp(tmpl);
    auto pc = herm::test::free_udp_port();
    auto pa = herm::test::free_udp_port();
    auto pb = herm::test::free_udp_port();
    // b takes no remote control: what tools ask of it (topics, type
    // descriptions) goes to its open herm.info APO.
    write("a.yaml", module_yaml("a", "0x21", pa, lo(pc) + "," + lo(pb), true)
                      + "apos:\n  - name: echo\n    kind: echo\n");
    write("b.yaml", module_yaml("b", "0x22", pb, lo(pa), false)
                      + "apos:\n  - name: echo.b\n    kind: echo\n");
    write("calc.yaml", module_yaml("calc", "0x20", pc, lo(pa), true));
    a_ = std::make_unique<child_process>(
      std::vector<std::string>{hermd, dir_ + "/a.yaml"});
    b_ = std::make_unique<child_process>(
      std::vector<std::string>{hermd, dir_ + "/b.yaml"});
    calc_ = std::make_unique<child_process>(std::vector<std::string>{
      calculator, "--config", dir_ + "/calc.yaml", "serve", "--seconds", "200"});
    // Converged when b reaches the calculator's module, two hops away.
    auto deadline = std::chrono::steady_clock::now() + 20s;
    std::string last;
    while (std::chrono::steady_clock::now() < deadline) {
      auto [rc, out] = run(ctl("b") + " ping 0x20 -c 1");
      if (rc == 0)
        return;
      last = out;
      std::this_thread::sleep_for(200ms);
    }
    FAIL() << "b never reached 0x20: " << last << "\ncalculator: "
           << calc_->output();
  }

  static void TearDownTestSuite() {
    calc_.reset();
    a_.reset();
    b_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  static std::string module_yaml(const std::string& name, const std::string& id,
                                 uint16_t port, const std::string& peers,
                                 bool remote_control) {
    return "module:\n  name: " + name + "\n  id: " + id
           + "\n  hello_interval_ms: 100\ncontrol:\n  socket: " + sock(name)
           + "\n  allow_unsigned_remote: "
           + (remote_control ? "true" : "false")
           + "\nchannels:\n  - name: eth0\n"
             "    kind: udp\n    interface: "
           + lo(port) + "\n    peers: " + peers + "\n";
  }

  static void write(const std::string& name, const std::string& text) {
    std::ofstream{dir_ + "/" + name} << text;
  }

  static std::string sock(const std::string& name) {
    return dir_ + "/" + name + ".sock";
  }

  static std::string ctl(const std::string& module) {
    return hermctl + " -s " + sock(module);
  }

  /// Runs a command to its end; stdout and stderr together.
  static std::pair<int, std::string> run(const std::string& cmd,
                                         std::chrono::seconds limit = 30s) {
    child_process p{{"/bin/sh", "-c", cmd + " 2>&1"}};
    auto status = p.wait(limit);
    return {status, p.output()};
  }

  /// Starts a command in the background (stderr dropped).
  static std::unique_ptr<child_process> start(const std::string& cmd) {
    return std::make_unique<child_process>(
      std::vector<std::string>{"/bin/sh", "-c", "exec " + cmd + " 2>/dev/null"});
  }

  /// Waits until `topic` has subscribers on at least `modules` modules, as
  /// module `m`'s topic list says; false after 10 s.
  static bool subscribed(const std::string& m, const std::string& topic,
                         size_t modules = 1) {
    auto deadline = std::chrono::steady_clock::now() + 10s;
    while (std::chrono::steady_clock::now() < deadline) {
      auto [rc, out] = run(ctl(m) + " --json topic list");
      auto j = json::parse(out, nullptr, false);
      if (rc == 0 && !j.is_discarded())
        for (auto& t : j["topics"])
          if (t["topic"] == topic && t["subscribers"].size() >= modules)
            return true;
      std::this_thread::sleep_for(100ms);
    }
    return false;
  }

  /// A recording's summary (record --info --json) and its count per topic.
  static std::pair<std::string, std::map<std::string, int>>
  recorded_counts(const std::string& file) {
    auto [rc, info] = run(hermctl + " --json record --info " + file);
    EXPECT_EQ(rc, 0) << info;
    std::map<std::string, int> counts;
    auto j = json::parse(info, nullptr, false);
    if (!j.is_discarded())
      for (auto& t : j["topics"])
        counts[t["topic"].get<std::string>()] = t["count"].get<int>();
    return {info, counts};
  }

  static inline std::string dir_;
  static inline std::unique_ptr<child_process> a_, b_, calc_;
};

TEST_F(hermctl_topics_test, pub_on_one_module_reaches_echo_on_another) {
  auto echo = start(ctl("b") + " --json topic echo greet -n 3");
  ASSERT_TRUE(subscribed("b", "greet"));
  for (auto word : {"one", "two", "three"}) {
    auto [rc, out] = run(ctl("a") + " topic pub greet " + word);
    ASSERT_EQ(rc, 0) << out;
    EXPECT_NE(out.find("publishing #1 on 'greet' (@str): \"" + std::string{word}),
              std::string::npos)
      << out;
  }
  ASSERT_EQ(echo->wait(20s), 0) << echo->output();
  auto lines = lines_of(echo->output());
  ASSERT_EQ(lines.size(), 3u) << echo->output();
  std::vector<std::string> values;
  for (auto& l : lines) {
    auto j = json::parse(l);
    EXPECT_EQ(j["topic"], "greet");
    EXPECT_EQ(j["publisher"], "0x21");
    EXPECT_EQ(j["types"], json::array({"@str"}));
    values.push_back(j["value"]);
  }
  EXPECT_EQ(values, (std::vector<std::string>{"one", "two", "three"}));
}

TEST_F(hermctl_topics_test, topic_list_names_publishers_and_subscribers_network_wide) {
  auto echo = start(ctl("b") + " topic echo listed");
  ASSERT_TRUE(subscribed("b", "listed"));
  ASSERT_EQ(run(ctl("a") + " topic pub listed 7 -t @u16").first, 0);
  auto [rc, out] = run(ctl("calc") + " --json topic list");
  ASSERT_EQ(rc, 0) << out;
  auto j = json::parse(out);
  EXPECT_EQ(j["modules"], 3);
  bool found = false;
  for (auto& t : j["topics"])
    if (t["topic"] == "listed") {
      found = true;
      EXPECT_EQ(t["type"], "@u16");
      EXPECT_EQ(t["publishers"], json::array({"0x21"}));
      EXPECT_EQ(t["subscribers"], json::array({"0x22"}));
    }
  EXPECT_TRUE(found) << out;
  auto [rc2, table] = run(ctl("calc") + " topic list");
  EXPECT_NE(table.find("TOPIC"), std::string::npos) << table;
  EXPECT_NE(table.find("listed"), std::string::npos) << table;
}

TEST_F(hermctl_topics_test, hz_reports_a_rate) {
  auto pub = start(ctl("a") + " topic pub ticks 1 -r 50 -n 200");
  auto [rc, out] = run(ctl("b") + " --json topic hz ticks -n 3");
  ASSERT_EQ(rc, 0) << out;
  auto lines = lines_of(out);
  ASSERT_EQ(lines.size(), 3u) << out;
  // The last report has a rate over a window of periods.
  auto j = json::parse(lines.back());
  ASSERT_TRUE(j.contains("rate_hz")) << out;
  EXPECT_GT(j["rate_hz"].get<double>(), 0.0);
  EXPECT_GT(j["window"].get<int>(), 1);
  EXPECT_LE(j["min_s"].get<double>(), j["max_s"].get<double>());
  auto [rc2, plain] = run(ctl("b") + " topic hz ticks -n 1");
  EXPECT_NE(plain.find("average rate: "), std::string::npos) << plain;
}

TEST_F(hermctl_topics_test, call_reaches_any_apo_with_values_in_the_text_form) {
  // A built-in type to hermd's echo APO on a, from b.
  auto [rc, out] = run(ctl("b") + " call echo '\"ping\"'");
  ASSERT_EQ(rc, 0) << out;
  EXPECT_EQ(out, "\"ping\"\n");
  // A type hermd describes, by field name, in its order.
  auto [rc2, out2] = run(ctl("b") + " --json call echo "
                         "'{\"seq\":3,\"distance_mm\":812,\"echo_us\":4734}' "
                         "-t herm::hermd::srf04_reading");
  ASSERT_EQ(rc2, 0) << out2;
  auto j = json::parse(out2);
  EXPECT_EQ(j["module"], "0x21");
  EXPECT_EQ(j["value"].dump(), R"({"seq":3,"distance_mm":812,"echo_us":4734})");
  // A user type only the calculator's process knows: b learns its
  // description from the calculator's herm.info, builds the request and
  // calls the APO through a proxy.
  auto [rc3, out3] = run(ctl("b") + " call calculator "
                         "'{\"a\":40,\"b\":2,\"op\":\"+\"}' -t calc_request");
  ASSERT_EQ(rc3, 0) << out3;
  EXPECT_EQ(out3, "42\n");
  // The APO's own error, typed.
  auto [rc4, out4] = run(ctl("b") + " call calculator "
                         "'{\"a\":7,\"b\":0,\"op\":\"/\"}' -t calc_request");
  EXPECT_EQ(rc4, 1);
  EXPECT_NE(out4.find("cannot compute 7 / 0 [invalid_parameter]"),
            std::string::npos)
    << out4;
  // A value that does not fit, and an APO nobody has.
  auto [rc5, out5] = run(ctl("b") + " call echo "
                         "'{\"seq\":70000,\"distance_mm\":1,\"echo_us\":1}' "
                         "-t herm::hermd::srf04_reading");
  EXPECT_EQ(rc5, 1);
  EXPECT_NE(out5.find("field 'seq': 70000 does not fit an unsigned 16-bit"),
            std::string::npos)
    << out5;
  auto [rc6, out6] = run(ctl("b") + " call nobody 1");
  EXPECT_EQ(rc6, 1);
  EXPECT_NE(out6.find("no APO named 'nobody' answered [not_found]"),
            std::string::npos)
    << out6;
  // An APO on a module that refuses remote control (b): a call is an
  // ordinary APO request, so a reaches it all the same.
  auto [rc8, out8] = run(ctl("a") + " call echo.b '[1, 2]' -t @i32,@i32");
  ASSERT_EQ(rc8, 0) << out8;
  EXPECT_EQ(out8, "[\n  1,\n  2\n]\n");
  // An APO that does not take the request's types: HERM's typed error,
  // never CAF's system.unexpected_message.
  auto [rc7, out7] = run(ctl("b") + " call calculator 5");
  EXPECT_EQ(rc7, 1);
  EXPECT_NE(out7.find("does not handle a message of this type [invalid_parameter]"),
            std::string::npos)
    << out7;
  EXPECT_EQ(out7.find("system."), std::string::npos) << out7;
}

TEST_F(hermctl_topics_test, echo_prints_a_user_type_by_field_name_learned_from_its_publisher) {
  // b's hermd was not built with calc_result: it asks the calculator's
  // module for the description.
  auto echo = start(ctl("b") + " topic echo calculator.results");
  ASSERT_TRUE(subscribed("b", "calculator.results"));
  for (auto req : {R"('{"a":6,"b":7,"op":"*"}')", R"('{"a":9,"b":1,"op":"-"}')"})
    ASSERT_EQ(run(ctl("b") + " call calculator " + req + " -t calc_request").first,
              0);
  // (The first value it prints may be the last one published before: a
  // late joiner gets it.)
  auto line = echo->wait_for_line_containing("\"a\":9", 20s);
  ASSERT_TRUE(line) << echo->output();
  EXPECT_EQ(*line, R"({"request":{"a":9,"b":1,"op":"-"},"value":8})")
    << echo->output();
  EXPECT_NE(echo->output().find(R"({"request":{"a":6,"b":7,"op":"*"},"value":42})"),
            std::string::npos)
    << echo->output();
  // A recording keeps the descriptions it needs, nested ones included.
  auto file = dir_ + "/calc.db";
  auto rec = start(ctl("b") + " record -o " + file + " calculator.results -n 1");
  // b subscribes already (echo), so the recorder gets no last value: the
  // next publication, whenever its subscription is in place.
  for (int i = 0; i < 50 && rec->running(); ++i)
    run(ctl("b") + R"( call calculator '{"a":1,"b":1,"op":"+"}' -t calc_request)");
  ASSERT_EQ(rec->wait(20s), 0) << rec->output();
  auto [rc, info] = run(hermctl + " --json record --info " + file);
  ASSERT_EQ(rc, 0) << info;
  EXPECT_EQ(json::parse(info)["described_types"], 2) << info;
}

TEST_F(hermctl_topics_test, a_module_without_remote_control_still_describes_its_types) {
  // The calculator's process was not built with hermd's types; b publishes
  // one and takes no remote control: calc learns the description from b's
  // open herm.info.
  auto echo = start(ctl("calc") + " topic echo sonar.b -n 1");
  ASSERT_TRUE(subscribed("calc", "sonar.b"));
  auto [rc, out] = run(ctl("b") + " topic pub sonar.b "
                       "'{\"seq\":5,\"distance_mm\":1200,\"echo_us\":6997}' "
                       "-t herm::hermd::srf04_reading");
  ASSERT_EQ(rc, 0) << out;
  ASSERT_EQ(echo->wait(20s), 0) << echo->output();
  EXPECT_EQ(echo->output(), "{\"seq\":5,\"distance_mm\":1200,\"echo_us\":6997}\n");
  // Remote control of b itself is refused, typed.
  auto [rc2, out2] = run(ctl("a") + " --module 0x22 info");
  EXPECT_EQ(rc2, 1);
  EXPECT_NE(out2.find("unauthorized"), std::string::npos) << out2;
}

TEST_F(hermctl_topics_test, record_then_play_into_a_fresh_subscriber_message_for_message) {
  auto file = dir_ + "/rec.db";
  auto rec = start(ctl("b") + " record -o " + file + " counted -n 5");
  ASSERT_TRUE(subscribed("b", "counted"));
  for (int i = 1; i <= 5; ++i)
    ASSERT_EQ(run(ctl("a") + " topic pub counted " + std::to_string(i * 11)
                  + " -t @i32")
                .first,
              0);
  ASSERT_EQ(rec->wait(20s), 0) << rec->output();
  EXPECT_NE(rec->output().find("recorded 5 messages into " + file),
            std::string::npos)
    << rec->output();
  auto [rc, info] = run(hermctl + " --json record --info " + file);
  ASSERT_EQ(rc, 0) << info;
  auto j = json::parse(info);
  EXPECT_EQ(j["messages"], 5);
  EXPECT_EQ(j["topics"][0]["topic"], "counted");
  EXPECT_EQ(j["topics"][0]["type"], "@i32");
  EXPECT_EQ(j["topics"][0]["count"], 5);
  const int64_t recorded_span = j["end_ns"].get<int64_t>() - j["start_ns"].get<int64_t>();
  // A fresh subscriber on a topic nobody published before, and one on the
  // playing module that takes the raw payload too.
  auto echo = start(ctl("b") + " --json topic echo counted.replay -n 5");
  auto raw = start(ctl("a") + " --json topic echo counted.replay -n 5 --raw");
  ASSERT_TRUE(subscribed("b", "counted.replay", 2));
  auto [rc2, played] = run(ctl("a") + " play " + file
                           + " --remap counted:=counted.replay -r 2");
  ASSERT_EQ(rc2, 0) << played;
  EXPECT_NE(played.find("played 5 messages"), std::string::npos) << played;
  ASSERT_EQ(echo->wait(20s), 0) << echo->output();
  ASSERT_EQ(raw->wait(20s), 0) << raw->output();
  auto lines = lines_of(echo->output());
  auto raw_lines = lines_of(raw->output());
  ASSERT_EQ(lines.size(), 5u) << echo->output();
  ASSERT_EQ(raw_lines.size(), 5u) << raw->output();
  for (int i = 0; i < 5; ++i) {
    auto v = json::parse(lines[i]);
    EXPECT_EQ(v["value"], (i + 1) * 11);
    EXPECT_EQ(v["types"], json::array({"@i32"}));
    EXPECT_FALSE(v.contains("payload")) << lines[i];
    // --raw: the same value, and its bytes as they travelled
    // (docs/protocol.md, "Payload layout"): version 1, one element, its
    // type name "@i32", then the i32, little-endian.
    auto r = json::parse(raw_lines[i]);
    EXPECT_EQ(r["value"], (i + 1) * 11);
    char hex[9];
    std::snprintf(hex, sizeof hex, "%02x000000", (i + 1) * 11);
    EXPECT_EQ(r["payload"], "01010440693332" + std::string{hex}) << raw_lines[i];
  }
  // Played at twice the speed: the values keep their spacing, halved. Not
  // all at once: at least 90 % of half the recorded span apart at b (the
  // upper side depends on the machine's load and is not asserted).
  auto played_span = json::parse(lines[4])["time_ns"].get<int64_t>()
                     - json::parse(lines[0])["time_ns"].get<int64_t>();
  EXPECT_GE(played_span, recorded_span * 9 / 20)
    << "recorded over " << recorded_span << " ns, played over " << played_span;
  // record refuses to overwrite; play refuses a file that is no recording.
  auto [rc3, again] = run(ctl("b") + " record -o " + file + " counted -n 1", 10s);
  EXPECT_EQ(rc3, 1);
  EXPECT_NE(again.find("exists already"), std::string::npos) << again;
  write("not.db", "hello");
  auto [rc4, bad] = run(ctl("a") + " play " + dir_ + "/not.db");
  EXPECT_EQ(rc4, 1);
  EXPECT_NE(bad.find("not.db"), std::string::npos) << bad;
}

TEST_F(hermctl_topics_test, play_loops_over_the_chosen_topics_until_interrupted) {
  auto file = dir_ + "/two.db";
  auto rec = start(ctl("b") + " record -o " + file + " loop.a loop.b -n 4");
  ASSERT_TRUE(subscribed("b", "loop.a") && subscribed("b", "loop.b"));
  int i = 0;
  for (auto topic : {"loop.a", "loop.b", "loop.a", "loop.b"})
    ASSERT_EQ(run(ctl("a") + " topic pub " + topic + " " + std::to_string(++i)
                  + " -t @i32")
                .first,
              0);
  ASSERT_EQ(rec->wait(20s), 0) << rec->output();
  // Only loop.a, again and again: 1, 3, 1, 3, ...
  auto echo = start(ctl("b") + " topic echo loop.again -n 6");
  ASSERT_TRUE(subscribed("b", "loop.again"));
  auto play = start(ctl("a") + " play " + file
                    + " --loop --topics loop.a --remap loop.a:=loop.again -r 20");
  ASSERT_EQ(echo->wait(30s), 0) << echo->output();
  EXPECT_EQ(echo->output(), "1\n3\n1\n3\n1\n3\n");
  ::kill(play->pid(), SIGINT);
  ASSERT_EQ(play->wait(10s), 0) << play->output();
  auto lines = lines_of(play->output());
  ASSERT_FALSE(lines.empty());
  uint64_t played = 0;
  ASSERT_EQ(std::sscanf(lines.back().c_str(), "played %lu messages", &played), 1)
    << play->output();
  // (The interrupt may cut the wait for the sixth one's reply: not counted.)
  EXPECT_GE(played, 5u);
  // Nothing of --topics in it: --loop ends at once instead of spinning.
  auto [rc, none] = run(ctl("a") + " play " + file + " --loop --topics loop.c", 10s);
  EXPECT_EQ(rc, 0) << none;
  EXPECT_NE(none.find("played 0 messages"), std::string::npos) << none;
}

TEST_F(hermctl_topics_test, record_without_topics_takes_those_that_appear_while_it_runs) {
  auto file = dir_ + "/every.db";
  ASSERT_EQ(run(ctl("a") + " topic pub every.early 1 -t @i32").first, 0);
  child_process rec{{"/bin/sh", "-c",
                     "exec " + ctl("b") + " record -o " + file + " -d 12 2>&1"}};
  ASSERT_TRUE(subscribed("b", "every.early")) << rec.output();
  // A topic born after the recording started: the recorder finds it when
  // it asks again (every 2 s), gets its last value, then the next one.
  ASSERT_EQ(run(ctl("a") + " topic pub every.late 2 -t @i32").first, 0);
  ASSERT_TRUE(subscribed("b", "every.late")) << rec.output();
  ASSERT_EQ(run(ctl("a") + " topic pub every.late 3 -t @i32").first, 0);
  ASSERT_EQ(rec.wait(40s), 0) << rec.output();
  EXPECT_NE(rec.output().find("and every new one"), std::string::npos)
    << rec.output();
  EXPECT_NE(rec.output().find("more topic(s): every.late"), std::string::npos)
    << rec.output();
  auto [info, counts] = recorded_counts(file);
  EXPECT_EQ(counts["every.early"], 1) << info;
  EXPECT_EQ(counts["every.late"], 2) << info;
}

// Every batch of new topics costs a control connection (a module serves
// 16 clients): past --max-subscriptions new topics are named and left out,
// and the recording goes on.
TEST_F(hermctl_topics_test, record_without_topics_opens_at_most_max_subscriptions) {
  auto file = dir_ + "/bounded.db";
  ASSERT_EQ(run(ctl("a") + " topic pub bounded.early 1 -t @i32").first, 0);
  child_process rec{{"/bin/sh", "-c",
                     "exec " + ctl("b") + " record -o " + file
                       + " -d 8 --max-subscriptions 1 2>&1"}};
  ASSERT_TRUE(subscribed("b", "bounded.early")) << rec.output();
  ASSERT_EQ(run(ctl("a") + " topic pub bounded.late 2 -t @i32").first, 0);
  ASSERT_TRUE(rec.wait_for_line_containing("not recording", 20s)) << rec.output();
  ASSERT_EQ(run(ctl("a") + " topic pub bounded.early 3 -t @i32").first, 0);
  ASSERT_EQ(rec.wait(40s), 0) << rec.output();
  EXPECT_NE(rec.output().find("1 subscriptions open (--max-subscriptions): "
                              "bounded.late"),
            std::string::npos)
    << rec.output();
  auto [info, counts] = recorded_counts(file);
  EXPECT_EQ(counts.count("bounded.late"), 0u) << info;
  EXPECT_EQ(counts["bounded.early"], 2) << info;
}

TEST_F(hermctl_topics_test, record_stops_after_its_duration) {
  auto file = dir_ + "/quiet.db";
  auto [rc, out] = run(ctl("b") + " record -o " + file + " nobody.publishes -d 1", 20s);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("recorded 0 messages into " + file), std::string::npos) << out;
  auto [rc2, info] = run(hermctl + " --json record --info " + file);
  ASSERT_EQ(rc2, 0) << info;
  EXPECT_EQ(json::parse(info)["messages"], 0);
}

TEST_F(hermctl_topics_test, bad_values_and_topics_are_refused_clearly) {
  auto [rc, out] = run(ctl("a") + " topic pub t '{\"x\":1}'");
  EXPECT_EQ(rc, 1);
  EXPECT_NE(out.find("give the value's \"type\""), std::string::npos) << out;
  auto [rc2, out2] = run(ctl("a") + " topic pub t 1 -t no::such");
  EXPECT_EQ(rc2, 1);
  EXPECT_NE(out2.find("type 'no::such' has no description here"),
            std::string::npos)
    << out2;
  auto [rc3, out3] = run(ctl("a") + " topic echo '' -n 1", 10s);
  EXPECT_EQ(rc3, 1);
  EXPECT_NE(out3.find("topic name"), std::string::npos) << out3;
  auto [rc4, out4] = run(ctl("a") + " --module 0x22 topic list");
  EXPECT_EQ(rc4, 2);
}

} // namespace
