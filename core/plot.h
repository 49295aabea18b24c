#pragma once
/// @file plot.h
/// @brief Drawing PNG charts with an external gnuplot (the gnuplot-nox package), for reports.
///
/// gnuplot is optional at run time: code that plots catches nothing and lets the Error reach
/// the command, which says how to install it. The PNG appears atomically: gnuplot draws into
/// PATH.partial, which is renamed over PATH only when gnuplot succeeded; on any failure no
/// partial file and no temporary script is left behind. Safe to call from several threads
/// for different output files.

#include <string>
#include <string_view>

namespace brickyard {

/// @brief `text` as a gnuplot single-quoted string literal: 'it''s' (a quote is doubled;
/// backslashes are literal). @throws Error(invalid_argument) for a line break or NUL, which a
/// gnuplot string cannot hold.
std::string gnuplot_quote(std::string_view text);

/// @brief Whether an executable `gnuplot` is on PATH (for callers that would rather skip a
/// plot than fail).
bool gnuplot_available();

/// @brief Runs gnuplot on `script_body` with a pngcairo terminal of width x height pixels
/// (font sans 11) whose output is `png_path`; `script_body` is everything that follows
/// `set output` (settings and plot commands). The script goes to a temporary file and
/// gnuplot's own output is captured, never printed.
/// @throws Error(unsupported) naming `png_path` when gnuplot is missing or fails (its last
/// message lines are in the text), Error(io) when the finished PNG cannot be moved into place.
void run_gnuplot(const std::string& script_body, const std::string& png_path, int width = 900, int height = 600);

}  // namespace brickyard
