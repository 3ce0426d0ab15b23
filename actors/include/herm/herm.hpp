#pragma once

// HERM for users: the one header a program that embeds HERM includes.
// docs/user-guide.md, "Writing an APO", walks through it.
//
//   #include <herm/herm.hpp>
//
//   struct calc_request { int32_t a = 0; int32_t b = 0; std::string op; };
//   HERM_MESSAGE(calc_request, a, b, op)              // inspect + field names
//   CAF_BEGIN_TYPE_ID_BLOCK(my_app, caf::id_block::herm::end)
//     CAF_ADD_TYPE_ID(my_app, (calc_request))
//   CAF_END_TYPE_ID_BLOCK(my_app)
//
//   caf::actor_system_config cfg;
//   herm::configure(cfg);                              // HERM's types, scheduler
//   herm::add_message_types<caf::id_block::my_app>(cfg);
//   caf::actor_system sys{cfg};
//   auto m = herm::serve_module(sys, mc, "arm");       // module + control socket
//   auto calc = herm::bind_within(sys, (*m)->apps, "calculator", 10s);
//
// What it brings in: the actor system set-up (configure), modules
// (module_config, run_module, serve_module), configuration files
// (load_config), the Application Support Layer (registering APOs, bind,
// topics), message types (HERM_MESSAGE, add_message_types, describe_type),
// HERM's typed errors (ec, routing_ec, app_ec, is, render, typed_error),
// and the CAF headers an APO needs.

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"
#include "caf/send.hpp"
#include "caf/type_id.hpp"

#include "actors/app_support.hpp"
#include "actors/config.hpp"
#include "actors/control.hpp"
#include "actors/embed.hpp"
#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "actors/type_description.hpp"
#include "actors/unexpected.hpp"
