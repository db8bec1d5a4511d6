#pragma once
// kinema, the runtime an engine embeds (library kinema::kinema): bodies, forces, methods,
// the stepper, job systems and diagnostics. Scenes, worlds and the accuracy tools are the
// separate library kinema::scene (kinema/scenes.hpp).

#include "kinema/adaptive.hpp"
#include "kinema/bodies.hpp"
#include "kinema/checkpoint.hpp"
#include "kinema/dense_output.hpp"
#include "kinema/diagnostics.hpp"
#include "kinema/error.hpp"
#include "kinema/events.hpp"
#include "kinema/files.hpp"
#include "kinema/forces.hpp"
#include "kinema/frame_loop.hpp"
#include "kinema/isa.hpp"
#include "kinema/job_system.hpp"
#include "kinema/methods.hpp"
#include "kinema/stability.hpp"
#include "kinema/stepper.hpp"
#include "kinema/version.hpp"
