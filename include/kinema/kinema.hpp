#pragma once
// kinema: a data-oriented time integrator for particles in games and simulations.

#include "kinema/accuracy.hpp"
#include "kinema/bodies.hpp"
#include "kinema/diagnostics.hpp"
#include "kinema/error.hpp"
#include "kinema/forces.hpp"
#include "kinema/isa.hpp"
#include "kinema/job_system.hpp"
#include "kinema/methods.hpp"
#include "kinema/scene.hpp"
#include "kinema/stepper.hpp"
#include "kinema/world.hpp"
