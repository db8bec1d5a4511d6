#pragma once
// Charts through gnuplot: each chart is a script written next to its data, rendered to
// SVG and PNG. The script stays in the output folder, so a chart can be restyled by hand.

#include <filesystem>
#include <string>

namespace kinema::cli {

// Runs `script` (gnuplot commands, without a terminal or output) twice, for
// DIR/NAME.svg and DIR/NAME.png. Throws kinema::Error when gnuplot fails or is missing.
void render_chart(const std::filesystem::path& dir, const std::string& name,
                  const std::string& script);

// Quotes text for a gnuplot string literal.
std::string gnuplot_quote(const std::string& text);

}  // namespace kinema::cli
