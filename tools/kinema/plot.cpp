#include "plot.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <sstream>

#include "interrupt.hpp"
#include "kinema/error.hpp"

extern char** environ;

namespace kinema::cli {

OutputFile::OutputFile(const std::filesystem::path& path) : std::ofstream(path), path_(path) {
  precision(17);
  if (!*this) throw Error(printable(path.string()) + ": cannot write: " + std::strerror(errno));
}

void OutputFile::close() {
  std::ofstream::close();
  if (!*this) throw Error(printable(path_.string()) + ": cannot write (disk full?)");
}

// Titles longer than this are cut: a chart title is one line.
constexpr std::size_t kMaxTitleBytes = 300;

// The SVG's text size, and the width of a character and the height of a row of the key as
// gnuplot's SVG terminal reckons them (measured on its output); a digit of DejaVu Sans is
// 0.64 em wide, so labels take that.
constexpr double kFontPixels = 13;
constexpr double kKeyCharPixels = 0.7 * kFontPixels;
constexpr double kKeyRowPixels = 1.5 * kFontPixels;
constexpr double kLabelFontPixels = 9;
constexpr double kLabelCharPixels = 0.64 * kLabelFontPixels;

std::string gnuplot_quote(const std::string& text) {
  std::string out = "'";
  for (char c : printable(text, kMaxTitleBytes)) {
    out += c;
    if (c == '\'') out += '\'';
  }
  return out + "'";
}

namespace {

// Runs gnuplot on the script `name` inside `dir`, without a shell, its stderr into `log`
// (a bare name in `dir` too). Returns the exit status, or -errno when it could not start.
int run_gnuplot(const std::filesystem::path& dir, const std::string& script,
                const std::string& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addchdir_np(&actions, dir.c_str());
  posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::string program = "gnuplot", argument = "./" + script;
  char* argv[] = {program.data(), argument.data(), nullptr};
  pid_t pid = 0;
  const int spawned = posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return -spawned;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -errno;
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// The last line gnuplot wrote that says what went wrong.
std::string last_complaint(const std::filesystem::path& log) {
  std::ifstream in(log);
  std::string line, last;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t^") != std::string::npos) last = line;
  }
  return printable(last);
}

}  // namespace

void render_chart(const std::filesystem::path& dir, const std::string& name,
                  const std::string& script, Canvas canvas) {
  const std::string size = std::to_string(canvas.width) + "," + std::to_string(canvas.height);
  const std::filesystem::path gp = dir / (name + ".gp");
  {
    std::ofstream out(gp);
    out << "set terminal svg size " << size << " dynamic noenhanced font 'sans," << kFontPixels
        << "' background rgb 'white'\n"
        << "set output '" << name << ".svg'\n"
        << script << "\n"
        // cairo's font points come out a third larger than the SVG's pixels: scaled back, the
        // labels placed for the SVG fit the PNG too.
        << "set terminal pngcairo size " << size << " noenhanced font 'sans," << kFontPixels
        << "' fontscale 0.75\n"
        << "set output '" << name << ".png'\n"
        << "replot\n";
    out.close();
    if (!out) throw Error(printable(gp.string()) + ": cannot write the chart script");
  }
  const std::string log = name + ".log";
  const int status = run_gnuplot(dir, name + ".gp", log);
  stop_if_interrupted();  // a Ctrl-C reaches gnuplot too: report the signal, not gnuplot
  if (status == -ENOENT) throw Error("gnuplot is not installed (Debian: gnuplot-nox)");
  if (status < 0) {
    throw Error("cannot start gnuplot in " + printable(dir.string()) + ": " + std::strerror(-status));
  }
  if (status != 0) {
    throw Error("gnuplot failed on " + printable(gp.string()) + ": " + last_complaint(dir / log));
  }
  std::filesystem::remove(dir / log);
}

std::vector<std::string> chart_files(const std::string& name) {
  return {name + ".gp", name + ".svg", name + ".png"};
}

MethodStyle method_style(std::string_view method) {
  // Colours far apart for the eye (and for colour-blind eyes as far as nine allow); the dash
  // tells the families apart: solid the classic Runge-Kutta methods, dashed the kick-drift
  // ones and heun (whose stability region is midpoint's), dash-dot the embedded pairs, long
  // dashes the implicit ones.
  static constexpr std::pair<std::string_view, MethodStyle> styles[] = {
      {"euler", {"#D55E00", 1, 7}},           {"midpoint", {"#56B4E9", 1, 5}},
      {"heun", {"#0072B2", 2, 9}},            {"rk4", {"#000000", 1, 13}},
      {"symplectic_euler", {"#E69F00", 2, 6}}, {"velocity_verlet", {"#009E73", 2, 4}},
      {"bs3", {"#CC79A7", 4, 8}},             {"dopri5", {"#7B3294", 4, 12}},
      {"rk6", {"#8C510A", 4, 11}},            {"implicit_euler", {"#999933", 5, 10}},
      {"ros2", {"#882255", 5, 3}},
  };
  for (const auto& [name, style] : styles) {
    if (name == method) return style;
  }
  return {"#999999", 3, 1};
}

std::string style_of(std::string_view method, bool with_point) {
  const MethodStyle s = method_style(method);
  return " lc rgb '" + std::string(s.colour) + "' dt " + std::to_string(s.dash) +
         (with_point ? " pt " + std::to_string(s.point) : "");
}

namespace {

std::string screen_fraction(double pixels, int extent) {
  char text[32];
  std::snprintf(text, sizeof text, "%.4f", pixels / extent);
  return text;
}

}  // namespace

std::string Frame::margins() const {
  return "set lmargin at screen " + screen_fraction(left, canvas.width) +
         "\nset rmargin at screen " + screen_fraction(canvas.width - right, canvas.width) +
         "\nset tmargin at screen " + screen_fraction(canvas.height - top, canvas.height) +
         "\nset bmargin at screen " + screen_fraction(bottom, canvas.height) + "\n";
}

double key_column_width(const std::vector<std::string>& titles) {
  std::size_t longest = 0;
  for (const std::string& t : titles) longest = std::max(longest, t.size());
  return (double(longest) + 6.1) * kKeyCharPixels;  // the title, the sample and the gaps
}

double key_height(std::size_t rows) { return double(rows) * kKeyRowPixels; }

std::string key_below(Frame& frame, const std::vector<std::string>& titles, double under_axis) {
  // gnuplot's own layout of a horizontal key: as many columns of the widest entry as the
  // plot's width takes, then as few columns as give that many rows.
  const double column = key_column_width(titles);
  const std::size_t entries = std::max<std::size_t>(1, titles.size());
  const std::size_t fit = std::clamp<std::size_t>(std::size_t(frame.width() / column), 1, entries);
  const std::size_t rows = (entries + fit - 1) / fit;
  const double key_top = 10 + key_height(rows);
  frame.bottom = key_top + under_axis;
  return frame.margins() + "set key at screen 0.5," + screen_fraction(key_top, frame.canvas.height) +
         " center top horizontal samplen 3 spacing 1 width 0 noautotitle\n";
}

LogAxis LogAxis::around(double lo, double hi) {
  // A twentieth of the span on each side, at least a factor of 1.3: no point on the frame.
  const double pad = std::max(1.3, std::pow(hi / lo, 0.05));
  return {lo / pad, hi * pad};
}

double LogAxis::fraction(double value) const {
  return std::log(value / lo) / std::log(hi / lo);
}

std::string LogAxis::range() const {
  char text[64];
  std::snprintf(text, sizeof text, "[%.4g:%.4g]", lo, hi);
  return text;
}

std::string LogAxis::tics(char axis) const {
  if (hi / lo >= 100) return "";
  std::string list;
  for (double decade = std::pow(10.0, std::floor(std::log10(lo))); decade <= hi; decade *= 10) {
    for (double m : {1, 2, 5}) {
      if (m * decade < lo || m * decade > hi) continue;
      char tic[32];
      std::snprintf(tic, sizeof tic, "%s%.3g", list.empty() ? "" : ", ", m * decade);
      list += tic;
    }
  }
  return std::string("set ") + axis + "tics (" + list + ")\n";
}

namespace {

struct Box {
  double left, top, right, bottom;

  bool overlaps(const Box& o) const {
    return left < o.right && o.left < right && top < o.bottom && o.top < bottom;
  }
  bool contains(Pixel p) const { return p.x >= left && p.x <= right && p.y >= top && p.y <= bottom; }
};

// Does the segment a-b cross the box? Clips the segment's parameter range against each slab.
bool crosses(Pixel a, Pixel b, const Box& box) {
  double t0 = 0, t1 = 1;
  const double d[2] = {b.x - a.x, b.y - a.y}, lo[2] = {box.left - a.x, box.top - a.y},
               hi[2] = {box.right - a.x, box.bottom - a.y};
  for (int k = 0; k < 2; ++k) {
    if (d[k] == 0) {
      if (lo[k] > 0 || hi[k] < 0) return false;
      continue;
    }
    double enter = lo[k] / d[k], leave = hi[k] / d[k];
    if (enter > leave) std::swap(enter, leave);
    t0 = std::max(t0, enter), t1 = std::min(t1, leave);
    if (t0 > t1) return false;
  }
  return true;
}

// Where a label may go around its point: beside, above, below and on the diagonals, then the
// same farther out. dx, dy: the anchor from the point; align: -1 the text ends at the anchor,
// 0 it is centred on it, 1 it starts there.
struct Spot {
  double dx, dy;
  int align;
};
constexpr Spot kSpots[] = {{11, 0, 1},  {-11, 0, -1}, {0, -14, 0},   {0, 14, 0},
                           {7, -12, 1}, {7, 12, 1},   {-7, -12, -1}, {-7, 12, -1}};

Box label_box(Pixel anchor, int align, const std::string& text) {
  const double w = double(text.size()) * kLabelCharPixels, h = 1.2 * kLabelFontPixels;
  const double left = anchor.x - (align < 0 ? w : align == 0 ? w / 2 : 0);
  return {left, anchor.y - h / 2, left + w, anchor.y + h / 2};
}

bool clear(const Box& box, const std::vector<Box>& taken, const std::vector<std::vector<Pixel>>& curves) {
  for (const Box& t : taken) {
    if (box.overlaps(t)) return false;
  }
  constexpr double marker = 8;  // half a point marker's width (ps 1.2), and a gap
  const Box padded{box.left - marker, box.top - marker, box.right + marker, box.bottom + marker};
  for (const auto& curve : curves) {
    for (std::size_t i = 0; i < curve.size(); ++i) {
      if (padded.contains(curve[i])) return false;
      if (i > 0 && crosses(curve[i - 1], curve[i], box)) return false;
    }
  }
  return true;
}

struct Placement {
  Pixel anchor;
  int align;
  Box box;
};

// The first spot around the label's point, nearest first, where it fits inside and is clear.
std::optional<Placement> find_place(const PointLabel& label, const Box& inside, const std::vector<Box>& taken,
                                    const std::vector<std::vector<Pixel>>& curves) {
  for (double reach : {1.0, 1.8}) {
    for (const Spot& s : kSpots) {
      const Pixel anchor{label.at.x + reach * s.dx, label.at.y + reach * s.dy};
      const Box box = label_box(anchor, s.align, label.text);
      const bool within = box.left >= inside.left && box.right <= inside.right &&
                          box.top >= inside.top && box.bottom <= inside.bottom;
      if (within && clear(box, taken, curves)) return Placement{anchor, s.align, box};
    }
  }
  return std::nullopt;
}

}  // namespace

std::string place_labels(const std::vector<PointLabel>& wanted,
                         const std::vector<std::vector<Pixel>>& curves, const Frame& frame) {
  const Box inside{frame.left + 2, frame.top + 2, frame.canvas.width - frame.right - 2,
                   frame.canvas.height - frame.bottom - 2};
  std::vector<Box> taken;
  std::string out;
  for (const PointLabel& label : wanted) {
    const std::optional<Placement> p = find_place(label, inside, taken, curves);
    if (!p) continue;
    taken.push_back({p->box.left - 2, p->box.top - 2, p->box.right + 2, p->box.bottom + 2});
    out += "set label " + gnuplot_quote(label.text) + " at screen " +
           screen_fraction(p->anchor.x, frame.canvas.width) + "," +
           screen_fraction(frame.canvas.height - p->anchor.y, frame.canvas.height) + " " +
           (p->align < 0 ? "right" : p->align == 0 ? "center" : "left") + " font '," +
           std::to_string(int(kLabelFontPixels)) + "' tc rgb '" + std::string(label.colour) + "' front\n";
  }
  return out;
}

}  // namespace kinema::cli
