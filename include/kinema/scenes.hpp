#pragma once
// kinema::scene, on top of the runtime: scene descriptions and their JSON files, generated
// bodies, worlds, reference solutions and the automatic choice of method.

#include "kinema/accuracy.hpp"
#include "kinema/kinema.hpp"
#include "kinema/scene.hpp"
#include "kinema/world.hpp"
