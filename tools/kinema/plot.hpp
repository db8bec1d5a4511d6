#pragma once
// Charts through gnuplot: each chart is a script written next to its data, rendered to
// SVG and PNG. The script stays in the output folder, so a chart can be restyled by hand.
//
// gnuplot runs inside the output folder and every file a script names is a bare name
// kinema chose (points_rk4.dat, energy.svg): no path a user typed ever becomes script text.
// The only user text in a script is a title, quoted by gnuplot_quote.

#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

namespace kinema::cli {

// A chart's size in pixels, the same for its SVG and its PNG.
struct Canvas {
  int width = 900;
  int height = 600;
};

// Runs `script` (gnuplot commands, without a terminal or output) twice, for
// DIR/NAME.svg and DIR/NAME.png, with DIR as gnuplot's working folder. Throws
// kinema::Error with gnuplot's own complaint when it fails, or when it is missing.
void render_chart(const std::filesystem::path& dir, const std::string& name,
                  const std::string& script, Canvas canvas = {});

// The files render_chart writes for `name`: its script, its SVG and its PNG.
std::vector<std::string> chart_files(const std::string& name);

// A gnuplot string literal holding `text` and nothing else: single quotes (no escapes, no
// backquote or macro expansion inside), a quote doubled, and every control character or
// invalid byte escaped as visible text (see printable), so the literal cannot end the line.
std::string gnuplot_quote(const std::string& text);

// How a method's curve looks: one fixed style per method, so a method looks the same in
// every chart, and no two methods share both colour and dash.
struct MethodStyle {
  std::string_view colour;  // #rrggbb
  int dash;                 // gnuplot dash type: 1 solid, 2 dashed, 4 dash-dot
  int point;                // gnuplot point type
};
MethodStyle method_style(std::string_view method);
// The style as gnuplot plot options: " lc rgb '#rrggbb' dt D pt P" (without pt: the caller
// draws its own points).
std::string style_of(std::string_view method, bool with_point = true);

// The plot frame's distances from the canvas' edges, in pixels. Fixed rather than left to
// gnuplot, so the plot area is known before gnuplot draws and labels can be placed on it.
struct Frame {
  Canvas canvas;
  double left = 100, right = 30, top = 45, bottom = 75;

  double width() const { return canvas.width - left - right; }
  double height() const { return canvas.height - top - bottom; }
  std::string margins() const;  // the gnuplot settings that put the frame there
};

// The width gnuplot gives a key column holding these titles, and the height of `rows` rows
// of a key, in pixels.
double key_column_width(const std::vector<std::string>& titles);
double key_height(std::size_t rows);

// The key under the x label, in as many columns as the canvas' width takes, so that the plot
// keeps the whole width: raises frame.bottom to make room and returns the gnuplot settings
// (the margins and the key). `under_axis`: pixels between the frame and the key, for the tic
// labels and the x label.
std::string key_below(Frame& frame, const std::vector<std::string>& titles, double under_axis = 62);

// A log axis a little wider than the positive values [lo, hi] it shows.
struct LogAxis {
  double lo, hi;

  static LogAxis around(double lo, double hi);
  double fraction(double value) const;  // 0 at lo, 1 at hi, on the log scale
  std::string range() const;            // gnuplot "[lo:hi]"
  // gnuplot tics at 1, 2 and 5 times the powers of ten when the axis spans under two decades
  // (gnuplot labels only whole decades, which may leave one label or none); else nothing.
  std::string tics(char axis) const;
};

// A point on the canvas, in pixels from its top left corner.
struct Pixel {
  double x, y;
};

struct PointLabel {
  Pixel at;  // the point labelled
  std::string text;
  std::string_view colour;
};

// gnuplot `set label` commands for the labels of `wanted` that fit beside their point, in
// order: each one inside the frame and clear of the labels placed before it, of every point
// and of every segment of `curves`. A label that fits nowhere is left out.
std::string place_labels(const std::vector<PointLabel>& wanted,
                         const std::vector<std::vector<Pixel>>& curves, const Frame& frame);

// An output file of the chart commands: an unwritable path fails when it is opened, and a
// failed write (a full disk) when it is closed; both throw kinema::Error naming the file.
class OutputFile : public std::ofstream {
 public:
  explicit OutputFile(const std::filesystem::path& path);
  void close();

 private:
  std::filesystem::path path_;
};

}  // namespace kinema::cli
