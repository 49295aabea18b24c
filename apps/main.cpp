// The `brickyard` command line. Library code throws brickyard::Error; only this file decides
// what the user sees and which exit code the process returns.

#include <exception>
#include <iostream>
#include <map>
#include <memory>
#include <new>
#include <string>

#include <tbb/global_control.h>

#include "apps/commands.h"
#include "core/error.h"
#include "core/progress.h"
#include "session/modules.h"

namespace {

/// What lowers a command's memory, for an allocation that failed: most commands check what
/// they need before they start (core/resources.h), so this is what their estimates missed.
std::string memory_options(const std::string& command) {
  static const std::map<std::string, std::string> options = {
      {"import", "a smaller --size or --brick-size; for meshes, fewer --cells or --replicate, or a smaller file"},
      {"generate", "a smaller --size"},
      {"render", "a smaller image (the scene's image.width and image.height) or cache budgets (cache.l1, cache.l2)"},
      {"bench", "a smaller --size or --reference-supersample, or the scene's cache budgets (cache.l1, cache.l2)"},
      {"flight", "smaller --l1 and --l2"},
      {"cachebench", "a smaller trace (fewer requests or objects in --synthetic) or fewer --sizes"},
  };
  const auto it = options.find(command);
  return (it == options.end() ? std::string() : it->second + ", or ") + "fewer threads (-j N before the subcommand)";
}

}  // namespace

int main(int argc, char** argv) {
  using namespace brickyard;
  CLI::App app{"brickyard: store, cache and render volumes far larger than memory", "brickyard"};
  app.require_subcommand(0, 1);  // checked below, so that an unknown word is named as such
  app.fallthrough();
  cli::GlobalOptions global;
  app.add_flag("-q,--quiet", global.quiet, "No progress output");
  app.add_option("-j,--threads", global.threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 4096));
  std::vector<std::string> modules;
  app.add_option("--module", modules,
                 "Load a back-end module (a shared library built against the installed package; repeatable; "
                 "BRICKYARD_MODULES adds more, separated by ':')");

  cli::add_generate_command(app, global);
  cli::add_version_command(app);
  int exit_status = 0;
  cli::add_store_commands(app, exit_status);
  cli::add_octree_commands(app);
  cli::add_cache_commands(app, exit_status);
  cli::add_render_commands(app, exit_status);

  std::unique_ptr<tbb::global_control> thread_limit;
  app.parse_complete_callback([&] {
    if (global.quiet) set_default_progress_style(ProgressStyle::quiet);
    if (global.threads > 0)
      thread_limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                           size_t(global.threads));
    // Before any subcommand runs: a module's back ends are chosen by name like the built-in ones.
    for (const std::string& path : modules_from_environment()) load_module(path);
    for (const std::string& path : modules) load_module(path);
  });

  try {
    app.parse(argc, argv);
    if (app.get_subcommands().empty()) {
      std::string names;
      for (const auto* sub : app.get_subcommands({})) names += (names.empty() ? "" : ", ") + sub->get_name();
      std::cerr << "brickyard: a subcommand is required (" << names << "); run with --help for more information\n";
      return 2;
    }
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);  // prints CLI11's message
    return 2;
  } catch (const Error& e) {
    std::cerr << "brickyard: error: " << e.what() << '\n';
    return exit_code(e.code());
  } catch (const std::bad_alloc&) {
    const auto parsed = app.get_subcommands();
    const std::string command = parsed.empty() ? std::string() : parsed.front()->get_name();
    std::cerr << "brickyard: error: " << (command.empty() ? "brickyard" : command)
              << " ran out of memory (an allocation failed); " << memory_options(command) << " lowers what it needs\n";
    return kExitOutOfResources;
  } catch (const std::exception& e) {
    std::cerr << "brickyard: error: " << e.what() << '\n';
    return 1;
  }
  return exit_status;
}
