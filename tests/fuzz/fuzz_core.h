// A session's deterministic core (server/sim_core.h) on a small built-in
// scene, without a network: what the command and journal targets drive.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <memory>

#include "server/sim_core.h"
#include "server/solid_builder.h"

namespace dynsolid::fuzz {

// block3 (27 control cells) at subdivision level 0, one stepping thread.
struct FuzzCore {
  server::SceneRequest request;
  server::SolidFactory factory;

  FuzzCore() {
    CreateSessionRequest create;
    create.set_builtin_scene("block3");
    create.set_levels_override(0);
    absl::StatusOr<server::SceneRequest> r = server::ResolveSceneRequest(create);
    if (!r.ok()) {
      std::fprintf(stderr, "fuzz core: %s\n", std::string(r.status().message()).c_str());
      std::abort();
    }
    request = *r;
    server::BuildLimits limits;
    limits.sim_threads = 1;
    factory = server::MakeSolidFactory(request, limits);
  }

  // A fresh core (running, not paused).
  std::unique_ptr<server::SimCore> Make() const {
    absl::StatusOr<std::shared_ptr<solid::Solid>> solid = factory(nullptr);
    if (!solid.ok()) {
      std::fprintf(stderr, "fuzz core: %s\n", std::string(solid.status().message()).c_str());
      std::abort();
    }
    return std::make_unique<server::SimCore>(*solid, server::CoreOptions(),
                                             /*start_paused=*/false, request.scene, factory);
  }
};

}  // namespace dynsolid::fuzz
