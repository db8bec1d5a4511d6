#include "plot.hpp"

#include <cstdlib>
#include <fstream>

#include "kinema/error.hpp"

namespace kinema::cli {

std::string gnuplot_quote(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

void render_chart(const std::filesystem::path& dir, const std::string& name,
                  const std::string& script) {
  const std::filesystem::path gp = dir / (name + ".gp");
  {
    std::ofstream out(gp);
    out << "set terminal svg size 900,600 dynamic noenhanced font 'sans,13' background rgb 'white'\n"
        << "set output " << gnuplot_quote((dir / (name + ".svg")).string()) << "\n"
        << script << "\n"
        << "set terminal pngcairo size 900,600 noenhanced font 'sans,11'\n"
        << "set output " << gnuplot_quote((dir / (name + ".png")).string()) << "\n"
        << "replot\n";
    if (!out) throw Error(gp.string() + ": cannot write the chart script");
  }
  const std::string command = "gnuplot " + gnuplot_quote(gp.string()) + " 2>" +
                              gnuplot_quote((dir / (name + ".log")).string());
  if (std::system(command.c_str()) != 0) {
    throw Error("gnuplot failed on " + gp.string() + " (is gnuplot-nox installed? see " +
                (dir / (name + ".log")).string() + ")");
  }
  std::filesystem::remove(dir / (name + ".log"));
}

}  // namespace kinema::cli
