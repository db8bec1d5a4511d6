#include "csv.hpp"

namespace kinema::bench::report {

Rk4Csv::Rk4Csv(const char* path, std::string isa) : file_(std::fopen(path, "w")), isa_(std::move(isa)) {
  if (file_ == nullptr) return;
  std::fprintf(file_, "precision,n,isa,ns_per_body_step,cv,ns_per_body_step_2t,speedup_naive,"
                      "speedup_odeint,ceiling_fraction,bandwidth_fraction,bandwidth_fraction_2t,"
                      "scaling_2t\n");
}

Rk4Csv::~Rk4Csv() {
  if (file_ != nullptr) std::fclose(file_);
}

void Rk4Csv::write(const Rk4Row& r) {
  if (file_ == nullptr) return;
  const auto one = std::optional<Figure>(r.one);
  std::fprintf(file_, "%s,%ld,%s,%.6g,%.4g,%s,%s,%s,%s,%s,%s,%s\n", r.p.c_str(), r.n, isa_.c_str(), r.one.median,
               r.one.cv, cell(median(r.two), "%.6g").c_str(), cell(ratio(r.naive, one), "%.4g").c_str(),
               cell(ratio(r.odeint, one), "%.4g").c_str(), cell(ratio(r.ceiling, one), "%.4g").c_str(),
               cell(r.bandwidth_one, "%.4g").c_str(), cell(r.bandwidth_two, "%.4g").c_str(),
               cell(ratio(one, r.two), "%.4g").c_str());
}

}  // namespace kinema::bench::report
