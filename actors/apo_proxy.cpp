#include "actors/apo_proxy.hpp"

#include "caf/actor_cast.hpp"
#include "caf/actor_config.hpp"
#include "caf/actor_proxy.hpp"
#include "caf/actor_system.hpp"
#include "caf/exit_reason.hpp"
#include "caf/make_actor.hpp"
#include "caf/system_messages.hpp"

#include "actors/runtime/atoms.hpp"
#include "actors/runtime/error.hpp"
#include "channels/thread_cache.hpp"

namespace herm::detail {

namespace {

/// Enqueues `xs` at `dst` as an anonymous asynchronous message: one
/// mailbox element holding the values, its block from the thread's cache
/// (a message made first and then enqueued would take two blocks).
template <class... Ts>
void post(const caf::strong_actor_ptr& dst, caf::execution_unit* ctx,
          Ts&&... xs) {
  dst->enqueue(make_pooled_element(nullptr, caf::make_message_id(),
                                   std::forward<Ts>(xs)...),
               ctx);
}

class apo_proxy final : public caf::actor_proxy {
public:
  apo_proxy(caf::actor_config& cfg, caf::weak_actor_ptr asl, uint32_t binding)
    : caf::actor_proxy(cfg), asl_(std::move(asl)), binding_(binding) {
    // nop
  }

  const char* name() const override {
    return "herm.proxy";
  }

  void enqueue(caf::mailbox_element_ptr what, caf::execution_unit* ctx) override {
    if (getf(is_terminated_flag)) {
      bounce(what, fail_state());
      return;
    }
    auto asl = asl_.lock();
    if (!asl) {
      bounce(what, make_error(routing_ec::no_route, "the application support layer "
                                            "of this module has stopped"));
      return;
    }
    auto& content = what->content();
    if (content.match_elements<caf::exit_msg>()) {
      // An exit message ends the binding, never the remote APO: stopping an
      // application object on another module is not a proxy's to decide.
      auto reason = content.get_as<caf::exit_msg>(0).reason;
      kill_proxy(ctx, std::move(reason));
      return;
    }
    auto mid = what->mid.integer_value();
    // Taken before take_content hands the element over.
    auto sender = std::move(what->sender);
    post(asl, ctx, atom::forward_v, binding_, std::move(sender), mid,
         take_content(what));
  }

  void kill_proxy(caf::execution_unit* ctx, caf::error reason) override {
    cleanup(std::move(reason), ctx);
  }

  void on_destroy() override {
    // The last handle is gone: monitors learn it like from any actor that
    // became unreachable, and the layer forgets the binding.
    if (auto asl = asl_.lock())
      post(asl, nullptr, atom::close_v, binding_);
    cleanup(caf::exit_reason::unreachable, nullptr);
  }

private:
  caf::weak_actor_ptr asl_;
  uint32_t binding_;
};

class reply_sink final : public caf::monitorable_actor {
public:
  reply_sink(caf::actor_config& cfg, caf::weak_actor_ptr asl)
    : caf::monitorable_actor(cfg), asl_(std::move(asl)) {
    // nop
  }

  const char* name() const override {
    return "herm.reply_sink";
  }

  void enqueue(caf::mailbox_element_ptr what, caf::execution_unit* ctx) override {
    // Only responses to the requests the layer made on behalf of remote
    // requesters come here; anything else has no one to go to.
    if (!what->mid.is_response())
      return;
    if (auto asl = asl_.lock())
      post(asl, ctx, atom::reply_v, what->mid.request_id().integer_value(),
           what->move_content_to_message());
  }

  void on_destroy() override {
    cleanup(caf::exit_reason::unreachable, nullptr);
  }

private:
  caf::weak_actor_ptr asl_;
};

} // namespace

caf::actor make_apo_proxy(caf::actor_system& sys, const caf::actor& asl,
                          uint32_t binding) {
  caf::actor_config cfg;
  auto ptr = caf::make_actor<apo_proxy, caf::strong_actor_ptr>(
    sys.next_actor_id(), sys.node(), &sys, cfg,
    caf::actor_cast<caf::weak_actor_ptr>(asl), binding);
  return caf::actor_cast<caf::actor>(std::move(ptr));
}

bool kill_apo_proxy(const caf::strong_actor_ptr& proxy, caf::error reason,
                    caf::execution_unit* ctx) {
  if (!proxy)
    return false;
  auto ptr = dynamic_cast<apo_proxy*>(proxy->get());
  if (ptr == nullptr || ptr->getf(caf::abstract_actor::is_terminated_flag))
    return false;
  ptr->kill_proxy(ctx, std::move(reason));
  return true;
}

caf::strong_actor_ptr make_reply_sink(caf::actor_system& sys,
                                      const caf::actor& asl) {
  caf::actor_config cfg;
  return caf::make_actor<reply_sink, caf::strong_actor_ptr>(
    sys.next_actor_id(), sys.node(), &sys, cfg,
    caf::actor_cast<caf::weak_actor_ptr>(asl));
}

} // namespace herm::detail
