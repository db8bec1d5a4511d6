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

namespace kinema::cli {

// Runs `script` (gnuplot commands, without a terminal or output) twice, for
// DIR/NAME.svg and DIR/NAME.png, with DIR as gnuplot's working folder. Throws
// kinema::Error with gnuplot's own complaint when it fails, or when it is missing.
void render_chart(const std::filesystem::path& dir, const std::string& name,
                  const std::string& script);

// A gnuplot string literal holding `text` and nothing else: single quotes (no escapes, no
// backquote or macro expansion inside), a quote doubled, and every control character or
// invalid byte escaped as visible text (see printable), so the literal cannot end the line.
std::string gnuplot_quote(const std::string& text);

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
