#pragma once
// The report's sections, in the order main() prints them. Each prints only what the run
// measured; the figures a section prints add their CV to the run's noise.
#include "noise.hpp"
#include "results.hpp"

namespace kinema::bench::report {

class Rk4Csv;

void print_rk4_table(const Results& results, Noise& noise, Rk4Csv* csv);
void print_methods_table(const Results& results);
void print_bounds_table(const Results& results, Noise& noise);
void print_frame_loop_table(const Results& results, Noise& noise);
void print_isa_table(const Results& results);
void print_rigid_table(const Results& results);
void print_game_table(const Results& results, Noise& noise);
void print_paired_scaling(const Results& results);
void print_coupled_table(const Results& results, Noise& noise);
void print_frame_table(const Results& results, Noise& noise);
void print_guard_table(const Results& results, Noise& noise);
void print_events_table(const Results& results, Noise& noise);
void print_adaptive_table(const Results& results, Noise& noise);
void print_checkpoint_table(const Results& results, Noise& noise);
void print_limits(const Results& results);

}  // namespace kinema::bench::report
