#pragma once
// The run's noise: the coefficient of variation of every figure the tables printed.
#include <algorithm>
#include <cstdio>
#include <vector>

namespace kinema::bench::report {

class Noise {
 public:
  void add(double cv) { cvs_.push_back(cv); }

  void print() const {
    if (cvs_.empty()) return;
    double max_cv = 0, sum = 0;
    for (double cv : cvs_) max_cv = std::max(max_cv, cv), sum += cv;
    std::printf("noise: coefficient of variation over repetitions, mean %.1f%%, max %.1f%% "
                "(differences below that are noise)\n",
                100 * sum / double(cvs_.size()), 100 * max_cv);
  }

 private:
  std::vector<double> cvs_;
};

}  // namespace kinema::bench::report
