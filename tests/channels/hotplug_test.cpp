// Hot-plug with real drivers and real threads: an emulated link's files
// disappear and come back; the channel ends with the reason, listeners learn
// it, and the IO manager re-creates the persistent channel with backoff.

#include <gtest/gtest.h>

#include <filesystem>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "channels/io_manager.hpp"
#include "channels/testing/null_modem.hpp"

using namespace herm;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

class hotplug : public ::testing::Test {
public:
  hotplug() : sys(init(cfg)), self(sys) {
    char tmpl[] = "/tmp/herm-hotplug-XXXXXX";
    dir = ::mkdtemp(tmpl);
    medium = dir + "/fw";
    fs::create_directories(medium);
    io = spawn_io_manager(sys, backoff_policy{50ms, 400ms});
    self->send(io, atom::subscribe_v, caf::actor_cast<io_listener_actor>(self));
  }

  ~hotplug() override {
    self->send_exit(io, caf::exit_reason::user_shutdown);
    std::error_code ec;
    fs::remove_all(dir, ec);
  }

  /// Waits for the next channel_up or channel_down (bounded).
  template <class T>
  std::optional<T> next(std::chrono::seconds timeout = 10s) {
    std::optional<T> result;
    auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!result && std::chrono::steady_clock::now() < deadline) {
      self->receive([&](T& x) { result = std::move(x); },
                    [&](channel_up&) {}, [&](channel_down&) {},
                    caf::after(200ms) >> [] {});
    }
    return result;
  }

  std::vector<channel_entry> table() {
    std::vector<channel_entry> result;
    self->request(io, 5s, atom::get_v, atom::channels_v)
      .receive([&](std::vector<channel_entry>& x) { result = std::move(x); },
               [](caf::error&) {});
    return result;
  }

  static caf::actor_system_config& init(caf::actor_system_config& c) {
    configure(c);
    return c;
  }

  caf::actor_system_config cfg;
  caf::actor_system sys;
  caf::scoped_actor self;
  std::string dir;
  std::string medium;
  io_manager_actor io;
};

} // namespace

TEST_F(hotplug, a_removed_link_file_ends_the_channel_and_it_comes_back) {
  device_config dev{"fw0", "emu", medium,
                    {{"profile", "ieee1394a"}, {"station", "1"}, {"create", "false"}}};
  caf::error err;
  self->request(io, 5s, atom::add_v, dev)
    .receive([](device_info&) {}, [&](caf::error& e) { err = e; });
  ASSERT_FALSE(err) << render(err);
  channel_id id = 0;
  self->request(io, 5s, atom::open_v, channel_request{"fw0", "*", true})
    .receive([&](channel_actor&, channel_info& info) { id = info.id; },
             [&](caf::error& e) { err = e; });
  ASSERT_FALSE(err) << render(err);
  auto up = next<channel_up>();
  ASSERT_TRUE(up);
  EXPECT_EQ(up->info.id, id);

  // Pull the station's file: the channel ends with a reason naming it.
  fs::remove(medium + "/1.sock");
  auto down = next<channel_down>();
  ASSERT_TRUE(down);
  EXPECT_EQ(down->id, id);
  EXPECT_TRUE(down->will_retry);
  EXPECT_TRUE(is(down->reason, ec::device_failed)) << render(down->reason);
  EXPECT_NE(render(down->reason).find("1.sock"), std::string::npos)
    << render(down->reason);
  // The medium is still there, so the first retry brings it back.
  up = next<channel_up>();
  ASSERT_TRUE(up);
  EXPECT_EQ(up->info.id, id);

  // Remove the whole medium: retries fail until it returns.
  fs::remove_all(medium);
  down = next<channel_down>();
  ASSERT_TRUE(down);
  EXPECT_TRUE(down->will_retry);
  std::this_thread::sleep_for(300ms);
  auto rows = table();
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].state, "retrying");
  EXPECT_NE(rows[0].last_error.find(medium), std::string::npos)
    << rows[0].last_error;
  fs::create_directories(medium);
  up = next<channel_up>();
  ASSERT_TRUE(up);
  EXPECT_EQ(up->info.id, id);
  rows = table();
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].state, "up");
  EXPECT_EQ(rows[0].restarts, 2u);
}

TEST_F(hotplug, a_serial_line_that_disappears_comes_back_when_it_reappears) {
  // The module's device path is a symlink (as udev gives a USB adapter a
  // stable name); the test points it at one end of a null-modem cable.
  std::string error;
  auto cable = herm::test::null_modem::open({}, error);
  ASSERT_TRUE(cable) << error;
  auto link = dir + "/ttyHERM";
  fs::create_symlink(cable->path_a(), link);
  device_config dev{"ser0", "serial", link, {{"baud", "115200"}}};
  caf::error err;
  self->request(io, 5s, atom::add_v, dev)
    .receive([](device_info&) {}, [&](caf::error& e) { err = e; });
  ASSERT_FALSE(err) << render(err);
  channel_id id = 0;
  self->request(io, 5s, atom::open_v, channel_request{"ser0", "*", true})
    .receive([&](channel_actor&, channel_info& info) { id = info.id; },
             [&](caf::error& e) { err = e; });
  ASSERT_FALSE(err) << render(err);
  ASSERT_TRUE(next<channel_up>());

  // Unplug: the line hangs up; the channel ends naming the device.
  cable->unplug();
  auto down = next<channel_down>();
  ASSERT_TRUE(down);
  EXPECT_EQ(down->id, id);
  EXPECT_TRUE(down->will_retry);
  EXPECT_NE(render(down->reason).find("ser0"), std::string::npos)
    << render(down->reason);
  // While the path points at nothing, retries fail.
  fs::remove(link);
  std::this_thread::sleep_for(300ms);
  auto rows = table();
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].state, "retrying");
  EXPECT_NE(rows[0].last_error.find("ttyHERM"), std::string::npos)
    << rows[0].last_error;

  // A new adapter appears under the same name: the channel comes back.
  auto cable2 = herm::test::null_modem::open({}, error);
  ASSERT_TRUE(cable2) << error;
  fs::create_symlink(cable2->path_a(), link);
  auto up = next<channel_up>();
  ASSERT_TRUE(up);
  EXPECT_EQ(up->info.id, id);
}
