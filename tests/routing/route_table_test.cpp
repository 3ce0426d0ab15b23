// The route table: the paper's routing entries (section 4.2), per-class
// selection (section 4.3, formula (1)), Babel's feasibility condition
// (RFC 8966 3.5.1) guarding against count-to-infinity, multiple paths,
// expiry with time passed in, and refusal of absurd input.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <iterator>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "routing/route_table.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

// -- helpers ---------------------------------------------------------------------

using time_point = route_table::time_point;

const time_point t0{};

constexpr auto hold = 10s;

constexpr module_id self_id = 0x4E;

metric_vector costs(metric c) {
  return {c, c, c, c};
}

metric_vector profile_metrics(const char* name) {
  return link_metrics(*find_profile(name));
}

/// `origin` as a neighbour advertises it: the same metric and path in every
/// class (hops = path length; no path where the metric is infinite).
advertised adv(module_id origin, seqno_t seqno, metric_vector metrics,
               std::vector<link_code> path = {}) {
  advertised a;
  a.origin = origin;
  a.seqno = seqno;
  a.metrics = metrics;
  for (size_t k = 0; k < size_classes; ++k) {
    if (metrics[k] == infinite_metric)
      continue;
    a.hops[k] = static_cast<uint8_t>(path.size());
    a.path[k] = path;
  }
  return a;
}

advertised adv(module_id origin, seqno_t seqno, metric m,
               std::vector<link_code> path = {}) {
  return adv(origin, seqno, costs(m), std::move(path));
}

advertised retraction(module_id origin, seqno_t seqno) {
  return adv(origin, seqno, infinite_metrics);
}

bool contains(const std::vector<module_id>& xs, module_id x) {
  return std::find(xs.begin(), xs.end(), x) != xs.end();
}

/// The row of (dest, via, class k), or nullopt.
std::optional<route_row> row_of(const route_table& t, module_id dest,
                                next_hop via, uint8_t k) {
  for (auto& r : t.rows())
    if (r.destination == dest && r.via == via && r.size_class == k)
      return r;
  return std::nullopt;
}

/// Applies one update at `now`; returns what changed (ASSERTs acceptance).
table_change feed(route_table& t, next_hop from, const advertised& a,
                  time_point now = t0) {
  table_change out;
  EXPECT_EQ(t.update(from, a, now, hold, out), update_result::accepted);
  return out;
}

// -- a small network of tables ------------------------------------------------------

/// Route tables wired by point-to-point links. Node i is module 0x10 + i and
/// its neighbours see it as next_hop{1, i}. Messages are snapshots of an
/// advertisement taken when sent, so they can arrive stale.
struct network {
  struct message {
    size_t from;
    size_t to;
    advertised adv;
  };

  std::vector<route_table> nodes;
  std::vector<std::vector<size_t>> links; // neighbours of each node
  std::vector<message> in_flight;

  explicit network(size_t n) : links(n) {
    for (size_t i = 0; i < n; ++i)
      nodes.emplace_back(id(i));
  }

  static module_id id(size_t i) {
    return static_cast<module_id>(0x10 + i);
  }

  static next_hop hop(size_t i) {
    return next_hop{1, static_cast<link_addr>(i)};
  }

  void link(size_t a, size_t b, metric_vector cost = costs(1)) {
    nodes[a].set_neighbour(hop(b), cost, link_code::ethernet);
    nodes[b].set_neighbour(hop(a), cost, link_code::ethernet);
    links[a].push_back(b);
    links[b].push_back(a);
  }

  void cut(size_t a, size_t b) {
    nodes[a].remove_neighbour(hop(b));
    nodes[b].remove_neighbour(hop(a));
    links[a].erase(std::find(links[a].begin(), links[a].end(), b));
    links[b].erase(std::find(links[b].begin(), links[b].end(), a));
  }

  bool linked(size_t a, size_t b) const {
    return std::find(links[a].begin(), links[a].end(), b) != links[a].end();
  }

  /// Node `from` tells `to` about `dest` right now.
  void send(size_t from, size_t to, module_id dest) {
    post(from, to, dest);
    deliver(in_flight.size() - 1);
  }

  /// Node `from` sends about `dest` to `to`; the message waits in flight.
  void post(size_t from, size_t to, module_id dest) {
    if (auto a = nodes[from].advertisement(dest))
      in_flight.push_back(message{from, to, *a});
  }

  /// Delivers (and removes) the message at `index` of in_flight. A message
  /// over a link cut meanwhile is refused by the receiver (unknown
  /// neighbour): exactly what the agent would see.
  table_change deliver(size_t index) {
    auto msg = in_flight[index];
    in_flight.erase(in_flight.begin() + static_cast<ptrdiff_t>(index));
    table_change out;
    nodes[msg.to].update(hop(msg.from), msg.adv, t0, hold, out);
    return out;
  }

  /// Every node tells every neighbour about `dest`, in node order.
  void round(module_id dest) {
    for (size_t i = 0; i < nodes.size(); ++i)
      for (auto j : links[i])
        send(i, j, dest);
  }

  /// The node `i` forwards to for `dest` in class k, if any.
  std::optional<size_t> next(size_t i, module_id dest, uint8_t k = 0) const {
    if (auto nh = nodes[i].lookup(dest, k))
      return static_cast<size_t>(nh->neighbour);
    return std::nullopt;
  }

  /// True if following next hops towards `dest` in class k from some node
  /// comes back to a node already visited.
  bool has_loop(module_id dest, uint8_t k) const {
    for (size_t start = 0; start < nodes.size(); ++start) {
      std::vector<bool> seen(nodes.size());
      for (auto at = std::optional<size_t>{start}; at; at = next(*at, dest, k)) {
        if (seen[*at])
          return true;
        seen[*at] = true;
      }
    }
    return false;
  }

  bool has_loop(module_id dest) const {
    for (uint8_t k = 0; k < size_classes; ++k)
      if (has_loop(dest, k))
        return true;
    return false;
  }
};

} // namespace

// -- the paper's entries -------------------------------------------------------------

TEST(route_table, installs_the_papers_example_entry) {
  // "when a module receives the pair, (8, CAN2.0) for the remote module,
  // 0x42 via the second channel with Ethernet interface, it adds the routing
  // entry, (0x42, 02, 8 plus computed cost, 2, CAN2.0-Ethernet)".
  route_table t{self_id};
  next_hop eth{2, 7};
  t.set_neighbour(eth, profile_metrics("ethernet"), link_code::ethernet);
  auto a = adv(0x42, 1, infinite_metrics);
  a.metrics[0] = 8;
  a.hops[0] = 1;
  a.path[0] = {link_code::can20};
  auto out = feed(t, eth, a);
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  auto row = row_of(t, 0x42, eth, 0);
  ASSERT_TRUE(row);
  EXPECT_EQ(row->via.channel, 2u);
  EXPECT_EQ(row->cost, 18u);
  EXPECT_EQ(row->hops, 2);
  // From here to the destination; the paper prints it origin-first.
  EXPECT_EQ(row->path,
            (std::vector<link_code>{link_code::ethernet, link_code::can20}));
  EXPECT_TRUE(row->selected);
  EXPECT_TRUE(row->feasible);
  EXPECT_EQ(t.lookup(0x42, 0), eth);
  EXPECT_EQ(t.reachable(), 1u);
  auto mine = t.advertisement(0x42);
  ASSERT_TRUE(mine);
  EXPECT_EQ(mine->metrics[0], 18u);
  EXPECT_EQ(mine->hops[0], 2);
  EXPECT_EQ(mine->path[0], row->path);
  EXPECT_EQ(mine->metrics[1], infinite_metric);
}

TEST(route_table, class_0_costs_of_direct_neighbours_are_table_1) {
  struct {
    const char* profile;
    link_code kind;
    metric cost;
  } cases[] = {
    {"usb1.1", link_code::usb11, 19},         {"usb2.0", link_code::usb20, 3},
    {"ieee1394a", link_code::ieee1394a, 4},   {"ieee1394b", link_code::ieee1394b, 1},
    {"can2.0", link_code::can20, 30},         {"ethernet", link_code::ethernet, 10},
    {"rs232c", link_code::rs232c, 47},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.profile);
    route_table t{self_id};
    next_hop nh{3, 1};
    t.set_neighbour(nh, profile_metrics(c.profile), c.kind);
    feed(t, nh, adv(0x42, 0, 0)); // the neighbour itself
    auto row = row_of(t, 0x42, nh, 0);
    ASSERT_TRUE(row);
    EXPECT_EQ(row->cost, c.cost);
    EXPECT_EQ(row->hops, 1);
    EXPECT_EQ(row->path, std::vector<link_code>{c.kind});
  }
}

TEST(route_table, path_choice_follows_the_packet_size) {
  // A destination one CAN hop away, or two hops away through an Ethernet
  // neighbour and a second link. Note: at Table 1's plain costs two Ethernet
  // hops (10 + 10) beat one CAN hop (30) even for 8 bytes; with a delay
  // coefficient of 2 on the Ethernet links (20 per hop) CAN wins class 0.
  auto slow_ethernet = *find_profile("ethernet");
  slow_ethernet.delay_coef = 2.0;
  struct {
    const char* name;
    link_profile first;  // our link to the Ethernet neighbour
    link_profile second; // its link to the destination
    link_code second_kind;
    bool small_takes_can;
  } cases[] = {
    {"ethernet then rs232c", *find_profile("ethernet"), *find_profile("rs232c"),
     link_code::rs232c, true},
    {"ethernet then ethernet, Table 1 costs", *find_profile("ethernet"),
     *find_profile("ethernet"), link_code::ethernet, false},
    {"ethernet then ethernet, delay coefficient 2", slow_ethernet,
     slow_ethernet, link_code::ethernet, true},
  };
  constexpr module_id dest = 0x42;
  next_hop can{1, 0x42};
  next_hop eth{2, 9};
  auto large = size_class_of(1000);
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    route_table t{self_id};
    t.set_neighbour(can, profile_metrics("can2.0"), link_code::can20);
    t.set_neighbour(eth, link_metrics(c.first), link_code::ethernet);
    feed(t, can, adv(dest, 0, 0));
    feed(t, eth, adv(dest, 0, link_metrics(c.second), {c.second_kind}));
    EXPECT_EQ(t.lookup(dest, 0), c.small_takes_can ? can : eth);
    EXPECT_EQ(t.lookup(dest, large), eth);
    auto row = row_of(t, dest, eth, large);
    ASSERT_TRUE(row);
    EXPECT_EQ(row->hops, 2);
    EXPECT_EQ(row->path,
              (std::vector<link_code>{link_code::ethernet, c.second_kind}));
  }
}

// -- sequence numbers and feasibility ---------------------------------------------------

TEST(route_table, seqnos_compare_modulo_2_16) {
  struct {
    seqno_t a;
    seqno_t b;
    bool newer;
  } cases[] = {
    {1, 65535, true},  {65535, 1, false}, {0, 65535, true},
    {5, 5, false},     {100, 99, true},   {99, 100, false},
    {0x7FFF, 0, true}, {0x8000, 0, false}, {0, 0x8000, false},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(std::to_string(c.a) + " vs " + std::to_string(c.b));
    EXPECT_EQ(seqno_newer(c.a, c.b), c.newer);
  }
}

TEST(route_table, feasibility_condition_against_the_selected_distance) {
  // Neighbour n1 advertises (fd_seqno, 5); with a link cost of 10 we select
  // it and the FD becomes (fd_seqno, 15). Then n2 advertises (seqno, m).
  struct {
    const char* name;
    seqno_t fd_seqno;
    seqno_t seqno;
    metric m;
    bool feasible;
  } cases[] = {
    {"same seqno, smaller metric", 100, 100, 14, true},
    {"same seqno, equal metric", 100, 100, 15, false},
    {"same seqno, larger metric", 100, 100, 16, false},
    {"newer seqno, much larger metric", 100, 101, 1000, true},
    {"older seqno, small metric", 100, 99, 1, false},
    {"newer across the wrap", 65535, 0, 1000, true},
    {"older across the wrap", 0, 65535, 1, false},
    {"retraction", 100, 100, infinite_metric, true},
  };
  next_hop n1{1, 1};
  next_hop n2{1, 2};
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    route_table t{self_id};
    t.set_neighbour(n1, costs(10), link_code::ethernet);
    t.set_neighbour(n2, costs(10), link_code::ethernet);
    feed(t, n1, adv(0x42, c.fd_seqno, 5, {link_code::can20}));
    // Create n2's route first so that a retraction has something to update.
    feed(t, n2, adv(0x42, c.fd_seqno, 14, {link_code::can20}));
    feed(t, n2, adv(0x42, c.seqno, c.m, {link_code::can20}));
    auto row = row_of(t, 0x42, n2, 0);
    ASSERT_TRUE(row);
    EXPECT_EQ(row->feasible, c.feasible);
    EXPECT_FALSE(row->selected);
    EXPECT_EQ(t.lookup(0x42, 0), n1);
  }
}

TEST(route_table, worse_metric_with_the_same_seqno_is_unfeasible) {
  // The count-to-infinity guard: a neighbour whose route got longer without
  // a new seqno may be routing through us.
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  feed(t, n, adv(0x42, 7, 5, {link_code::can20}));
  ASSERT_EQ(t.lookup(0x42, 0), n);
  auto out = feed(t, n, adv(0x42, 7, 20, {link_code::can20}));
  EXPECT_EQ(t.lookup(0x42, 0), std::nullopt);
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_EQ(out.starving, std::vector<module_id>{0x42});
  auto row = row_of(t, 0x42, n, 0);
  ASSERT_TRUE(row);
  EXPECT_FALSE(row->feasible);
  EXPECT_FALSE(row->selected);
  EXPECT_EQ(row->cost, 30u); // kept, just never selected
  // We retract it meanwhile, and tell which seqno we wait for.
  auto mine = t.advertisement(0x42);
  ASSERT_TRUE(mine);
  EXPECT_EQ(mine->metrics, infinite_metrics);
  EXPECT_EQ(mine->seqno, 7);
  EXPECT_EQ(t.reachable(), 0u);
}

TEST(route_table, a_newer_seqno_makes_the_route_feasible_again) {
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  feed(t, n, adv(0x42, 7, 5, {link_code::can20}));
  feed(t, n, adv(0x42, 7, 20, {link_code::can20}));
  ASSERT_EQ(t.lookup(0x42, 0), std::nullopt);
  auto out = feed(t, n, adv(0x42, 8, 20, {link_code::can20}));
  EXPECT_EQ(t.lookup(0x42, 0), n);
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_TRUE(out.starving.empty());
  EXPECT_EQ(t.advertisement(0x42)->metrics[0], 30u);
  EXPECT_EQ(t.advertisement(0x42)->seqno, 8);
}

TEST(route_table, a_retraction_is_always_accepted) {
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  feed(t, n, adv(0x42, 7, 5, {link_code::can20}));
  // Same seqno and an (infinitely) worse metric: still accepted.
  auto out = feed(t, n, retraction(0x42, 7));
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_TRUE(out.starving.empty()); // nothing finite to wait for
  EXPECT_EQ(t.lookup(0x42, 0), std::nullopt);
  EXPECT_EQ(t.advertisement(0x42)->metrics, infinite_metrics);
  auto row = row_of(t, 0x42, n, 0);
  ASSERT_TRUE(row);
  EXPECT_TRUE(row->feasible);
  EXPECT_EQ(row->cost, infinite_metric);
  // A retraction of a route we never had is accepted and ignored.
  table_change none;
  EXPECT_EQ(t.update(n, retraction(0x77, 1), t0, hold, none),
            update_result::accepted);
  EXPECT_TRUE(none.changed.empty());
  EXPECT_EQ(t.advertisement(0x77), std::nullopt);
}

TEST(route_table, starving_is_reported_until_a_feasible_route_arrives) {
  next_hop n1{1, 1};
  next_hop n2{1, 2};
  route_table t{self_id};
  t.set_neighbour(n1, costs(10), link_code::ethernet);
  t.set_neighbour(n2, costs(10), link_code::ethernet);
  feed(t, n1, adv(0x42, 3, 0));
  feed(t, n2, adv(0x42, 3, 10, {link_code::ethernet})); // FD (3, 10): unfeasible
  auto out = t.remove_neighbour(n1);
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_EQ(out.starving, std::vector<module_id>{0x42});
  // Every further unfeasible update says it again (the agent rate-limits).
  out = feed(t, n2, adv(0x42, 3, 10, {link_code::ethernet}));
  EXPECT_TRUE(out.changed.empty());
  EXPECT_EQ(out.starving, std::vector<module_id>{0x42});
  // The origin answered the seqno request.
  out = feed(t, n2, adv(0x42, 4, 10, {link_code::ethernet}));
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_TRUE(out.starving.empty());
  EXPECT_EQ(t.lookup(0x42, 0), n2);
}

TEST(route_table, starving_in_one_class_alone_is_reported_too) {
  // Class 2 has only an unfeasible route while the others are fine: without
  // a seqno request class 2 would never recover.
  next_hop n1{1, 1};
  next_hop n2{1, 2};
  route_table t{self_id};
  t.set_neighbour(n1, costs(10), link_code::ethernet);
  t.set_neighbour(n2, costs(10), link_code::ethernet);
  feed(t, n1, adv(0x42, 3, 0));
  feed(t, n2, adv(0x42, 3, metric_vector{5, 5, 50, 5}, {link_code::ethernet}));
  auto out = t.remove_neighbour(n1);
  EXPECT_EQ(t.lookup(0x42, 0), n2);
  EXPECT_EQ(t.lookup(0x42, 2), std::nullopt);
  EXPECT_EQ(out.starving, std::vector<module_id>{0x42});
  EXPECT_EQ(t.advertisement(0x42)->metrics, (metric_vector{15, 15, infinite_metric, 15}));
  EXPECT_EQ(t.advertisement(0x42)->seqno, 3);
}

// -- count to infinity ---------------------------------------------------------------

TEST(route_table, two_nodes_do_not_count_to_infinity) {
  // D(0) - B(1) - A(2). The link D-B fails; B's and A's messages then cross
  // in either order. Neither may select a route through the other.
  constexpr size_t d = 0, b = 1, a = 2;
  const module_id dest = network::id(d);
  struct step {
    size_t from;
    size_t to;
  };
  const std::vector<step> orders[] = {
    {{a, b}, {b, a}, {a, b}, {b, a}}, // A's stale route reaches B first
    {{b, a}, {a, b}, {b, a}, {a, b}}, // B's retraction reaches A first
  };
  for (auto& order : orders) {
    network net{3};
    net.link(d, b);
    net.link(b, a);
    net.round(dest);
    net.round(dest);
    ASSERT_EQ(net.next(b, dest), d);
    ASSERT_EQ(net.next(a, dest), b);
    // B heard A's route back (metric 2 against B's FD 1): kept, unfeasible.
    auto echo = row_of(net.nodes[b], dest, network::hop(a), 0);
    ASSERT_TRUE(echo);
    EXPECT_FALSE(echo->feasible);
    net.post(a, b, dest); // A's stale route, in flight while the link fails
    net.nodes[d].remove_neighbour(network::hop(b));
    auto out = net.nodes[b].remove_neighbour(network::hop(d));
    EXPECT_EQ(out.changed, std::vector<module_id>{dest});
    EXPECT_EQ(out.starving, std::vector<module_id>{dest});
    EXPECT_EQ(net.next(b, dest), std::nullopt);
    net.deliver(0);
    EXPECT_EQ(net.next(b, dest), std::nullopt);
    for (auto& s : order) {
      net.send(s.from, s.to, dest);
      EXPECT_EQ(net.next(b, dest), std::nullopt);
      EXPECT_FALSE(net.has_loop(dest));
    }
    EXPECT_EQ(net.next(a, dest), std::nullopt);
    EXPECT_EQ(net.next(b, dest), std::nullopt);
  }
}

TEST(route_table, three_nodes_do_not_count_to_infinity) {
  // D(0) hangs off A(1); A, B(2), C(3) form a triangle. The link D-A fails.
  // RIP with split horizon loops here (A learns D back from C through B);
  // feasibility must not. Stale messages cross in several orders.
  constexpr size_t d = 0, a = 1, b = 2, c = 3;
  const module_id dest = network::id(d);
  struct step {
    size_t from;
    size_t to;
  };
  const std::vector<step> orders[] = {
    {{c, a}, {b, a}, {a, b}, {a, c}, {b, c}, {c, b}},
    {{a, b}, {b, c}, {c, a}, {a, c}, {c, b}, {b, a}},
    {{a, c}, {c, b}, {b, a}, {a, b}, {b, c}, {c, a}},
    {{b, c}, {c, a}, {a, b}, {b, a}, {a, c}, {c, b}},
  };
  for (size_t i = 0; i < std::size(orders); ++i) {
    SCOPED_TRACE("order " + std::to_string(i));
    network net{4};
    net.link(d, a);
    net.link(a, b);
    net.link(a, c);
    net.link(b, c);
    net.round(dest);
    net.round(dest);
    ASSERT_EQ(net.next(a, dest), d);
    ASSERT_EQ(net.next(b, dest), a);
    ASSERT_EQ(net.next(c, dest), a);
    // B and C both keep the route through each other, unfeasible (2 vs 2).
    auto bc = row_of(net.nodes[b], dest, network::hop(c), 0);
    ASSERT_TRUE(bc);
    EXPECT_EQ(bc->cost, 3u);
    EXPECT_FALSE(bc->feasible);
    // Stale advertisements of B and C are in flight towards A and each other.
    const std::pair<size_t, size_t> stale[] = {{b, a}, {c, a}, {b, c}, {c, b}};
    for (auto [from, to] : stale)
      net.post(from, to, dest);
    net.cut(d, a);
    EXPECT_EQ(net.next(a, dest), std::nullopt);
    while (!net.in_flight.empty()) {
      net.deliver(0);
      EXPECT_EQ(net.next(a, dest), std::nullopt);
      EXPECT_FALSE(net.has_loop(dest));
    }
    for (int repeat = 0; repeat < 2; ++repeat) {
      for (auto& s : orders[i]) {
        net.send(s.from, s.to, dest);
        EXPECT_EQ(net.next(a, dest), std::nullopt);
        EXPECT_FALSE(net.has_loop(dest));
      }
    }
    EXPECT_EQ(net.next(a, dest), std::nullopt);
    EXPECT_EQ(net.next(b, dest), std::nullopt);
    EXPECT_EQ(net.next(c, dest), std::nullopt);
  }
}

TEST(route_table, classes_with_different_seqnos_advertise_the_oldest) {
  // D(0) - A(1) - B(2) - C(3) - D. B routes class 0 through C and class 1
  // through A. D's new seqno reaches B through C first: B's class-0 route
  // has seqno 1, its class-1 route (through A) still 0. If B labelled its
  // class-1 metric with seqno 1, A, cut from D, would take it as feasible
  // and route class 1 to B, which routes it back to A.
  constexpr size_t d = 0, a = 1, b = 2, c = 3;
  const module_id dest = network::id(d);
  network net{4};
  net.link(d, a, costs(1));
  net.link(a, b, metric_vector{10, 1, 1, 1});
  net.link(b, c, metric_vector{1, 10, 10, 10});
  net.link(c, d, metric_vector{1, 10, 10, 10});
  for (int i = 0; i < 3; ++i)
    net.round(dest);
  ASSERT_EQ(net.next(b, dest, 0), c);
  ASSERT_EQ(net.next(b, dest, 1), a);
  net.nodes[d].bump_own_seqno();
  net.send(d, c, dest);
  net.send(c, b, dest);
  ASSERT_EQ(net.next(b, dest, 0), c);
  ASSERT_EQ(net.next(b, dest, 1), a);
  EXPECT_EQ(net.nodes[b].advertisement(dest)->seqno, 0);
  net.cut(d, a);
  net.send(b, a, dest);
  EXPECT_EQ(net.next(a, dest, 1), std::nullopt);
  EXPECT_FALSE(net.has_loop(dest));
}

TEST(route_table, random_failures_and_stale_messages_never_form_loops) {
  // Ten tables on a random mesh with per-class costs from Table 1 profiles;
  // messages are delivered late and out of order while links fail and come
  // back, and origins bump their seqno when someone starves. After every
  // delivery no class may loop for any destination.
  const char* profiles[] = {"can2.0", "ethernet", "rs232c", "usb1.1",
                            "ieee1394a"};
  constexpr size_t n = 10;
  std::mt19937 rng{20240611};
  auto pick = [&](size_t bound) {
    return std::uniform_int_distribution<size_t>{0, bound - 1}(rng);
  };
  for (int trial = 0; trial < 8; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    network net{n};
    std::vector<std::pair<size_t, size_t>> edges;
    for (size_t i = 1; i < n; ++i)
      edges.emplace_back(pick(i), i); // a spanning tree
    for (int extra = 0; extra < 6; ++extra) {
      auto x = pick(n), y = pick(n);
      if (x != y && !net.linked(x, y)
          && std::find(edges.begin(), edges.end(), std::pair{y, x})
               == edges.end()
          && std::find(edges.begin(), edges.end(), std::pair{x, y})
               == edges.end())
        edges.emplace_back(x, y);
    }
    std::vector<metric_vector> edge_cost;
    for (auto [x, y] : edges) {
      edge_cost.push_back(profile_metrics(profiles[pick(std::size(profiles))]));
      net.link(x, y, edge_cost.back());
    }
    for (int step = 0; step < 4000; ++step) {
      auto action = pick(1000);
      if (action < 25) { // a node sends its whole table to its neighbours
        auto i = pick(n);
        for (auto dest : net.nodes[i].destinations())
          for (auto j : net.links[i])
            net.post(i, j, dest);
      } else if (action < 975) {
        if (net.in_flight.empty())
          continue;
        auto index = pick(net.in_flight.size());
        auto dest = net.in_flight[index].adv.origin;
        auto out = net.deliver(index);
        for (auto s : out.starving) // the seqno request reaches the origin
          net.nodes[s - 0x10].bump_own_seqno();
        ASSERT_FALSE(net.has_loop(dest)) << "step " << step;
      } else if (action < 987) { // a link fails
        auto e = pick(edges.size());
        auto [x, y] = edges[e];
        if (net.linked(x, y))
          net.cut(x, y);
      } else { // or comes back
        auto e = pick(edges.size());
        auto [x, y] = edges[e];
        if (!net.linked(x, y))
          net.link(x, y, edge_cost[e]);
      }
      if (step % 100 == 0) {
        for (size_t dest = 0; dest < n; ++dest)
          ASSERT_FALSE(net.has_loop(network::id(dest))) << "step " << step;
      }
    }
    // Quiet again: late messages land, then full rounds (answering seqno
    // requests) until every node routes to every node it is connected to.
    while (!net.in_flight.empty())
      net.deliver(pick(net.in_flight.size()));
    for (size_t r = 0; r < 3 * n; ++r) {
      for (size_t i = 0; i < n; ++i) {
        for (auto dest : net.nodes[i].destinations()) {
          for (auto j : net.links[i]) {
            net.post(i, j, dest);
            auto out = net.deliver(net.in_flight.size() - 1);
            for (auto s : out.starving)
              net.nodes[s - 0x10].bump_own_seqno();
          }
        }
      }
    }
    for (size_t i = 0; i < n; ++i) {
      std::vector<bool> connected(n);
      std::vector<size_t> todo{i};
      connected[i] = true;
      while (!todo.empty()) {
        auto x = todo.back();
        todo.pop_back();
        for (auto y : net.links[x])
          if (!connected[y]) {
            connected[y] = true;
            todo.push_back(y);
          }
      }
      for (size_t dest = 0; dest < n; ++dest) {
        SCOPED_TRACE("from " + std::to_string(i) + " to " + std::to_string(dest));
        for (uint8_t k = 0; k < size_classes; ++k) {
          auto expected = connected[dest] && dest != i;
          EXPECT_EQ(net.next(i, network::id(dest), k).has_value(), expected);
          EXPECT_FALSE(net.has_loop(network::id(dest), k));
        }
      }
    }
  }
}

// -- multiple paths and neighbours ---------------------------------------------------

TEST(route_table, keeps_every_path_and_fails_over_to_the_next_best) {
  route_table t{self_id};
  next_hop n1{1, 1};
  next_hop n2{2, 5};
  t.set_neighbour(n1, costs(10), link_code::ethernet);
  t.set_neighbour(n2, costs(10), link_code::ieee1394a);
  feed(t, n1, adv(0x42, 1, 5, {link_code::can20}));
  feed(t, n2, adv(0x42, 1, 8, {link_code::rs232c}));
  auto rows = t.rows();
  ASSERT_EQ(rows.size(), 2 * size_classes);
  // Sorted by destination, class, cost: n1 (15) before n2 (18) in class 0.
  EXPECT_EQ(rows[0].via, n1);
  EXPECT_EQ(rows[0].cost, 15u);
  EXPECT_TRUE(rows[0].selected);
  EXPECT_EQ(rows[1].via, n2);
  EXPECT_EQ(rows[1].cost, 18u);
  EXPECT_FALSE(rows[1].selected);
  EXPECT_TRUE(rows[1].feasible); // 8 < 15: ready to take over
  EXPECT_EQ(t.lookup(0x42, 0), n1);
  auto out = t.remove_neighbour(n1);
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_TRUE(out.starving.empty());
  EXPECT_EQ(t.lookup(0x42, 0), n2);
  EXPECT_EQ(t.advertisement(0x42)->metrics[0], 18u);
  EXPECT_EQ(t.advertisement(0x42)->path[0],
            (std::vector<link_code>{link_code::ieee1394a, link_code::rs232c}));
  EXPECT_EQ(t.rows().size(), size_classes);
  // Updates from a removed neighbour are refused until it is set again.
  table_change none;
  EXPECT_EQ(t.update(n1, adv(0x42, 1, 5, {link_code::can20}), t0, hold, none),
            update_result::unknown_neighbour);
}

TEST(route_table, equal_routes_break_ties_by_hops_then_next_hop) {
  route_table t{self_id};
  next_hop n1{1, 1};
  next_hop n2{1, 2};
  next_hop n3{2, 0};
  for (auto nh : {n1, n2, n3})
    t.set_neighbour(nh, costs(10), link_code::ethernet);
  feed(t, n2, adv(0x42, 1, 10, {link_code::ethernet, link_code::ethernet}));
  feed(t, n3, adv(0x42, 1, 10, {link_code::ethernet}));
  feed(t, n1, adv(0x42, 1, 10, {link_code::ethernet}));
  EXPECT_EQ(t.lookup(0x42, 0), n1); // 20 in 2 hops like n3; lower next hop
  t.remove_neighbour(n1);
  EXPECT_EQ(t.lookup(0x42, 0), n3); // 2 hops against n2's 3
}

TEST(route_table, a_neighbours_new_cost_moves_the_selection) {
  route_table t{self_id};
  next_hop n1{1, 1};
  next_hop n2{1, 2};
  t.set_neighbour(n1, costs(10), link_code::ethernet);
  t.set_neighbour(n2, costs(10), link_code::ethernet);
  feed(t, n1, adv(0x42, 1, 5, {link_code::can20}));
  feed(t, n2, adv(0x42, 1, 6, {link_code::can20}));
  EXPECT_TRUE(t.set_neighbour(n1, costs(10), link_code::ethernet).changed.empty());
  auto out = t.set_neighbour(n1, costs(30), link_code::ethernet);
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_EQ(t.lookup(0x42, 0), n2);
  EXPECT_EQ(t.advertisement(0x42)->metrics[0], 16u);
}

TEST(route_table, remove_channel_drops_all_its_neighbours_at_once) {
  route_table t{self_id};
  next_hop a{1, 1};
  next_hop b{1, 2};
  next_hop c{2, 1};
  for (auto nh : {a, b, c})
    t.set_neighbour(nh, costs(10), link_code::ethernet);
  feed(t, a, adv(0x42, 1, 1, {link_code::can20}));
  feed(t, b, adv(0x42, 1, 2, {link_code::can20}));
  feed(t, c, adv(0x42, 1, 3, {link_code::can20}));
  feed(t, b, adv(0x43, 1, 0));
  ASSERT_EQ(t.lookup(0x42, 0), a);
  ASSERT_EQ(t.reachable(), 2u);
  auto out = t.remove_channel(1);
  EXPECT_EQ(out.changed, (std::vector<module_id>{0x42, 0x43})); // once each
  EXPECT_EQ(t.lookup(0x42, 0), c);
  EXPECT_EQ(t.lookup(0x43, 0), std::nullopt);
  EXPECT_EQ(t.reachable(), 1u);
  for (auto& r : t.rows())
    EXPECT_EQ(r.via.channel, 2u);
  // 0x43 lost its last route: advertised as retracted until it would have
  // expired, then forgotten.
  EXPECT_EQ(t.advertisement(0x43)->metrics, infinite_metrics);
  EXPECT_TRUE(contains(t.destinations(), 0x43));
  t.expire(t0 + hold);
  EXPECT_EQ(t.advertisement(0x43), std::nullopt);
  EXPECT_FALSE(contains(t.destinations(), 0x43));
  EXPECT_TRUE(t.remove_channel(7).changed.empty());
}

// -- expiry -------------------------------------------------------------------------

TEST(route_table, routes_expire_after_hold_unless_refreshed) {
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  feed(t, n, adv(0x42, 1, 5, {link_code::can20}), t0);
  auto out = feed(t, n, adv(0x42, 1, 5, {link_code::can20}), t0 + 5s);
  EXPECT_TRUE(out.changed.empty()); // a refresh changes nothing
  EXPECT_EQ(t.next_expiry(), t0 + 15s);
  struct {
    std::chrono::seconds at;
    bool routed;
    bool advertised; // known at all (retracted or not)
    bool changed;
    std::chrono::seconds next; // next_expiry() afterwards
  } timeline[] = {
    {9s, true, true, false, 15s},   // within the first hold
    {14s, true, true, false, 15s},  // refreshed at 5s: expires at 15s
    {15s, false, true, true, 25s},  // expired: retracted, reported
    {20s, false, true, false, 25s}, // still advertised as retracted
    // Forgotten one hold later; its source is kept for 5 minutes.
    {25s, false, false, false, 325s},
  };
  for (auto& step : timeline) {
    SCOPED_TRACE(std::to_string(step.at.count()) + "s");
    out = t.expire(t0 + step.at);
    EXPECT_EQ(t.next_expiry(), t0 + step.next);
    EXPECT_EQ(t.lookup(0x42, 0).has_value(), step.routed);
    EXPECT_EQ(t.advertisement(0x42).has_value(), step.advertised);
    EXPECT_EQ(contains(out.changed, 0x42), step.changed);
    if (step.advertised && !step.routed) {
      EXPECT_EQ(t.advertisement(0x42)->metrics, infinite_metrics);
    }
  }
  EXPECT_TRUE(t.rows().empty());
  EXPECT_EQ(t.destinations(), std::vector<module_id>{self_id});
}

TEST(route_table, feasibility_distances_are_forgotten_long_after_the_routes) {
  // After routes to 0x42 are gone, an older seqno stays unfeasible while
  // the source is remembered, and is accepted once it has been forgotten
  // (max(3 x the longest hold, 5 min) after the destination was).
  struct {
    std::chrono::seconds idle;
    bool feasible;
  } cases[] = {{60s, false}, {299s, false}, {300s, true}, {3600s, true}};
  next_hop n{1, 1};
  for (auto& c : cases) {
    SCOPED_TRACE(std::to_string(c.idle.count()) + "s");
    route_table t{self_id};
    t.set_neighbour(n, costs(10), link_code::ethernet);
    feed(t, n, adv(0x42, 50, 5, {link_code::can20}), t0);
    t.expire(t0 + 10s); // expired, retracted
    t.expire(t0 + 20s); // forgotten; the source becomes idle now
    ASSERT_EQ(t.advertisement(0x42), std::nullopt);
    t.expire(t0 + 20s + c.idle);
    feed(t, n, adv(0x42, 40, 90, {link_code::can20}), t0 + 20s + c.idle);
    EXPECT_EQ(t.lookup(0x42, 0).has_value(), c.feasible);
  }
}

// -- absurd input ------------------------------------------------------------------------

TEST(route_table, refuses_absurd_updates_and_changes_nothing) {
  next_hop n{1, 1};
  auto valid = [] { return adv(0x42, 1, 5, {link_code::can20}); };
  struct {
    const char* name;
    std::function<void(advertised&, next_hop&)> spoil;
    update_result why = update_result::malformed;
  } cases[] = {
    {"origin is us", [](advertised& a, next_hop&) { a.origin = self_id; }},
    {"origin is broadcast",
     [](advertised& a, next_hop&) { a.origin = broadcast_module; }},
    {"origin is none", [](advertised& a, next_hop&) { a.origin = no_module; }},
    {"200 hops",
     [](advertised& a, next_hop&) {
       a.hops[1] = 200;
       a.path[1].assign(200, link_code::can20);
     }},
    {"path longer than hops",
     [](advertised& a, next_hop&) { a.path[0].push_back(link_code::usb20); }},
    {"path shorter than hops", [](advertised& a, next_hop&) { a.hops[2] = 3; }},
    {"unknown neighbour", [](advertised&, next_hop& from) { from.neighbour = 9; },
     update_result::unknown_neighbour},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    route_table t{self_id};
    t.set_neighbour(n, costs(10), link_code::ethernet);
    auto a = valid();
    auto from = n;
    c.spoil(a, from);
    table_change out;
    EXPECT_EQ(t.update(from, a, t0, hold, out), c.why);
    EXPECT_TRUE(out.changed.empty());
    EXPECT_TRUE(out.starving.empty());
    EXPECT_TRUE(t.rows().empty());
    EXPECT_EQ(t.destinations(), std::vector<module_id>{self_id});
    EXPECT_EQ(t.update(n, valid(), t0, hold, out),
              update_result::accepted); // the control
  }
}

TEST(route_table, an_infinite_class_needs_no_path) {
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  auto a = adv(0x42, 1, 5, {link_code::can20});
  a.metrics[3] = infinite_metric;
  a.hops[3] = 250; // ignored
  a.path[3].clear();
  feed(t, n, a);
  EXPECT_EQ(t.lookup(0x42, 0), n);
  EXPECT_EQ(t.lookup(0x42, 3), std::nullopt);
  EXPECT_EQ(t.lookup(0x42, size_classes), std::nullopt); // no such class
}

TEST(route_table, a_route_beyond_max_hops_is_unreachable) {
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(1), link_code::ethernet);
  std::vector<link_code> longest(max_route_hops, link_code::ethernet);
  feed(t, n, adv(0x42, 1, 32, longest)); // we would be 33 hops away
  EXPECT_EQ(t.lookup(0x42, 0), std::nullopt);
  std::vector<link_code> shorter(max_route_hops - 1, link_code::ethernet);
  feed(t, n, adv(0x43, 1, 31, shorter));
  EXPECT_EQ(t.lookup(0x43, 0), n);
  EXPECT_EQ(t.advertisement(0x43)->hops[0], max_route_hops);
}

TEST(route_table, huge_metrics_saturate_instead_of_wrapping) {
  struct {
    const char* name;
    metric advertised;
    metric link;
    metric cost;
  } cases[] = {
    {"just below infinity", infinite_metric - 1, 10, infinite_metric},
    {"sum reaches infinity", infinite_metric - 10, 10, infinite_metric},
    {"sum just below infinity", infinite_metric - 11, 10, infinite_metric - 1},
    {"infinite link", 5, infinite_metric, infinite_metric},
    {"zero link cost counts as 1", 5, 0, 6},
  };
  next_hop n{1, 1};
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    route_table t{self_id};
    t.set_neighbour(n, costs(c.link), link_code::ethernet);
    feed(t, n, adv(0x42, 1, c.advertised, {link_code::can20}));
    auto row = row_of(t, 0x42, n, 0);
    ASSERT_TRUE(row);
    EXPECT_EQ(row->cost, c.cost);
    EXPECT_EQ(t.lookup(0x42, 0).has_value(), c.cost != infinite_metric);
    EXPECT_EQ(t.advertisement(0x42)->metrics[0], c.cost);
  }
}

// -- ourselves ----------------------------------------------------------------------------

TEST(route_table, advertises_itself_with_its_own_seqno) {
  route_table t{self_id};
  EXPECT_EQ(t.self(), self_id);
  EXPECT_EQ(t.destinations(), std::vector<module_id>{self_id});
  EXPECT_EQ(t.advertisement(0x42), std::nullopt);
  for (int i = 0; i < 65536 + 3; ++i)
    t.bump_own_seqno();
  EXPECT_EQ(t.own_seqno(), 3); // wraps around
  auto mine = t.advertisement(self_id);
  ASSERT_TRUE(mine);
  EXPECT_EQ(mine->origin, self_id);
  EXPECT_EQ(mine->seqno, 3);
  EXPECT_EQ(mine->metrics, (metric_vector{0, 0, 0, 0}));
  for (size_t k = 0; k < size_classes; ++k) {
    EXPECT_EQ(mine->hops[k], 0);
    EXPECT_TRUE(mine->path[k].empty());
  }
  EXPECT_EQ(t.lookup(self_id, 0), std::nullopt);
}

TEST(route_table, renumbering_drops_routes_to_the_new_id_and_keeps_the_seqno) {
  route_table t{0x4E};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  t.bump_own_seqno();
  feed(t, n, adv(0x0120, 9, 0));
  feed(t, n, adv(0x0130, 9, 0));
  ASSERT_EQ(t.reachable(), 2u);
  t.set_self(0x0120);
  EXPECT_EQ(t.self(), 0x0120);
  EXPECT_EQ(t.own_seqno(), 1);
  EXPECT_EQ(t.lookup(0x0120, 0), std::nullopt);
  EXPECT_EQ(t.lookup(0x0130, 0), n); // other routes stay
  EXPECT_EQ(t.reachable(), 1u);
  EXPECT_EQ(t.advertisement(0x0120)->metrics, (metric_vector{0, 0, 0, 0}));
  EXPECT_EQ(t.destinations(), (std::vector<module_id>{0x0120, 0x0130}));
  for (auto& r : t.rows())
    EXPECT_NE(r.destination, 0x0120);
  table_change out;
  EXPECT_EQ(t.update(n, adv(0x0120, 9, 0), t0, hold, out),
            update_result::malformed);
  // The neighbour echoes our old id back with our seqno: never a route
  // (it would lead back to us). A new holder's newer seqno is.
  feed(t, n, adv(0x4E, 1, 10, {link_code::ethernet}));
  EXPECT_EQ(t.lookup(0x4E, 0), std::nullopt);
  feed(t, n, adv(0x4E, 2, 10, {link_code::ethernet}));
  EXPECT_EQ(t.lookup(0x4E, 0), n);
}

TEST(route_table, moves_keep_the_table) {
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  feed(t, n, adv(0x42, 1, 0));
  route_table moved{std::move(t)};
  EXPECT_EQ(moved.lookup(0x42, 0), n);
  route_table other{0x10};
  other = std::move(moved);
  EXPECT_EQ(other.self(), self_id);
  EXPECT_EQ(other.lookup(0x42, 0), n);
}

// -- bounds ---------------------------------------------------------------------------------

// Neighbours decide how much they advertise; the table decides how much it
// keeps. Each case has neighbours advertise destinations 0x1000 + i in turn
// and says how many of each are kept and why the rest are refused.
TEST(route_table, refuses_new_routes_past_each_bound_and_keeps_the_held_ones) {
  struct {
    const char* name;
    route_limits limits;
    /// Destinations each neighbour advertises (neighbour j: next_hop{1, j+1}),
    /// all from 0x1000 on (so two neighbours advertise the same ones).
    std::vector<size_t> advertised;
    std::vector<size_t> kept;
    update_result why;
    size_t destinations;
  } cases[] = {
    {"one neighbour past its share", {100, 10, 100}, {30}, {10},
     update_result::over_share, 10},
    {"a second neighbour has a share of its own", {100, 10, 100}, {30, 30},
     {10, 10}, update_result::over_share, 10},
    {"past the total of destinations", {16, 100, 100}, {30}, {16},
     update_result::over_limit, 16},
    {"the total is shared by all neighbours", {16, 100, 100}, {10, 30},
     {10, 16}, update_result::over_limit, 16},
    {"past the total of routes", {100, 100, 25}, {20, 20}, {20, 5},
     update_result::over_limit, 20},
  };
  for (auto& c : cases) {
    SCOPED_TRACE(c.name);
    route_table t{self_id, c.limits};
    std::vector<next_hop> nbs;
    for (size_t j = 0; j < c.advertised.size(); ++j) {
      nbs.push_back(next_hop{1, j + 1});
      t.set_neighbour(nbs.back(), costs(10), link_code::ethernet);
    }
    for (size_t j = 0; j < nbs.size(); ++j) {
      size_t accepted = 0;
      for (size_t i = 0; i < c.advertised[j]; ++i) {
        table_change out;
        auto res = t.update(nbs[j], adv(static_cast<module_id>(0x1000 + i), 1, 5),
                            t0, hold, out);
        if (res == update_result::accepted)
          ++accepted;
        else
          EXPECT_EQ(res, c.why) << i;
      }
      EXPECT_EQ(accepted, c.kept[j]) << j;
      EXPECT_EQ(t.routes_from(nbs[j]), c.kept[j]) << j;
    }
    EXPECT_EQ(t.size(), c.destinations);
    EXPECT_LE(t.size(), c.limits.destinations);
    EXPECT_LE(t.routes(), c.limits.routes);
    // What is held keeps being refreshed (past the hold) and served.
    auto later = t0 + hold - 1s;
    for (size_t i = 0; i < c.kept[0]; ++i)
      feed(t, nbs[0], adv(static_cast<module_id>(0x1000 + i), 2, 5), later);
    t.expire(t0 + hold);
    for (size_t i = 0; i < c.kept[0]; ++i)
      EXPECT_EQ(t.lookup(static_cast<module_id>(0x1000 + i), 0), nbs[0]) << i;
    // A retraction is always taken, and what it frees (once its tombstone
    // is gone) takes new routes again.
    feed(t, nbs[0], retraction(0x1000, 3), later);
    EXPECT_EQ(t.lookup(0x1000, 0), std::nullopt);
    for (size_t j = 0; j < nbs.size(); ++j)
      t.remove_neighbour(nbs[j]);
    t.expire(t0 + 10 * hold);
    EXPECT_EQ(t.size(), 0u);
    EXPECT_EQ(t.routes(), 0u);
    t.set_neighbour(nbs[0], costs(10), link_code::ethernet);
    feed(t, nbs[0], adv(0x2000, 1, 5), t0 + 10 * hold);
    EXPECT_EQ(t.lookup(0x2000, 0), nbs[0]);
  }
}

TEST(route_table, a_route_held_is_refreshed_when_the_table_is_full) {
  route_table t{self_id, route_limits{2, 2, 4}};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  feed(t, n, adv(0x42, 1, 5));
  feed(t, n, adv(0x43, 1, 5));
  table_change out;
  EXPECT_EQ(t.update(n, adv(0x44, 1, 5), t0, hold, out),
            update_result::over_limit);
  // A new seqno and metric for a held destination: taken and advertised.
  out = feed(t, n, adv(0x42, 2, 7));
  EXPECT_EQ(out.changed, std::vector<module_id>{0x42});
  EXPECT_EQ(t.advertisement(0x42)->metrics[0], 17u);
  // A retraction of a destination never held is no news, not a refusal.
  EXPECT_EQ(t.update(n, retraction(0x45, 1), t0, hold, out),
            update_result::accepted);
  EXPECT_EQ(t.size(), 2u);
}

// Every destination that goes leaves its origin's feasibility distance
// behind for minutes; a neighbour that keeps advertising new origins and
// dropping them must not make those pile up.
TEST(route_table, idle_sources_are_kept_no_more_than_the_destination_bound) {
  route_table t{self_id, route_limits{4, 4, 16}};
  next_hop n{1, 1};
  auto now = t0;
  constexpr size_t rounds = 10;
  for (size_t round = 0; round < rounds; ++round) {
    t.set_neighbour(n, costs(10), link_code::ethernet);
    for (size_t i = 0; i < 4; ++i)
      feed(t, n, adv(static_cast<module_id>(0x1000 + 4 * round + i), 1, 5), now);
    EXPECT_EQ(t.reachable(), 4u);
    t.remove_neighbour(n);
    now += 2 * hold; // past the tombstones, far within the source hold
    t.expire(now);
    EXPECT_EQ(t.size(), 0u);
  }
  EXPECT_EQ(t.sources_evicted(), 4 * (rounds - 1));
}

// Two neighbours that hold retracted routes from each other keep
// advertising the retraction to each other; that must not keep the
// destination (and its room in the table) for ever.
TEST(route_table, repeated_retractions_do_not_keep_a_route_alive) {
  route_table t{self_id};
  next_hop n{1, 1};
  t.set_neighbour(n, costs(10), link_code::ethernet);
  feed(t, n, adv(0x42, 1, 5));
  feed(t, n, retraction(0x42, 1));
  EXPECT_EQ(t.lookup(0x42, 0), std::nullopt);
  // Retracted again and again, every half hold: still gone after the hold
  // the first retraction set, and its tombstone after another.
  for (auto at = t0 + hold / 2; at < t0 + 3 * hold; at += hold / 2) {
    feed(t, n, retraction(0x42, 1), at);
    t.expire(at);
  }
  EXPECT_EQ(t.size(), 0u);
  EXPECT_EQ(t.routes(), 0u);
  // A new advertisement after a retraction is taken (and refreshed) again.
  feed(t, n, adv(0x42, 2, 5), t0 + 3 * hold);
  EXPECT_EQ(t.lookup(0x42, 0), n);
  feed(t, n, adv(0x42, 2, 5), t0 + 3 * hold + hold / 2);
  t.expire(t0 + 4 * hold);
  EXPECT_EQ(t.lookup(0x42, 0), n);
}
