// clipstream-merge: joins the partial stores of a sharded clipstream-tile run
// (--shard K/N) into one store. Thin: argument parsing, signals and the
// summary; the work is mergeShards() in the tiler library (shard.h).
#include <clipstream/cli/cli.h>
#include <clipstream/cli/progress.h>
#include <clipstream/tiler/shard.h>
#include <clipstream/tiler/tiler.h>

#include <cstdio>
#include <iostream>
#include <memory>

namespace {
std::atomic<int> g_cancel{0};
}  // namespace

int main(int argc, char** argv) {
  using namespace clipstream;
  CLI::App app{"Joins the partial stores of a sharded clipstream-tile run (--shard K/N) into one "
               "store, building the coarse levels no shard holds alone.",
               "clipstream-merge"};
  std::vector<std::string> positional;
  uint64_t memory_mb = 256;
  bool quiet = false, force = false, no_fsync = false;
  std::string order_text;
  app.add_option("OUTPUT PARTS", positional, "the output store, then every partial store (any order)")
      ->required()
      ->expected(2, -1);
  app.add_option("--memory-mb", memory_mb, "bound on the coarse levels' row buffers in MiB")
      ->transform(cli::wholeInRange(int64_t(kMinMemoryBudgetBytes >> 20), int64_t(1) << 30));
  app.add_flag("--quiet,-q", quiet, "no progress bar and no summary");
  app.add_flag("--force,-f", force, "overwrite an existing OUTPUT (a regular file, never a part)");
  app.add_flag("--no-fsync", no_fsync, "skip the final fsync (faster, for scratch outputs)");
  app.add_option("--payload-order", order_text,
                 "where tiles lie in each level: curve or written (default " +
                     std::string(payloadOrderName(MergeOptions{}.payload_order)) + ")");
  app.footer(
      "Exit codes: 0 success, 1 failure (nothing left behind), 2 command-line mistake,\n"
      "128+N stopped by signal N. docs/tiler.md (Sharded runs), docs/cli.md.");
  if (std::optional<int> code = cli::parse(app, argc, argv)) return *code;

  MergeOptions options;
  options.output_path = positional[0];
  options.input_paths.assign(positional.begin() + 1, positional.end());
  for (const std::string& p : positional) {
    if (p.empty()) return cli::usageError(app, "OUTPUT and PARTS must not be empty");
  }
  options.overwrite = force;
  options.fsync = !no_fsync;
  options.memory_budget_bytes = memory_mb << 20;
  if (!order_text.empty()) {
    const std::optional<PayloadOrder> order = cli::parsePayloadOrder(order_text);
    if (!order) return cli::usageError(app, "--payload-order must be curve or written");
    options.payload_order = *order;
  }
  std::unique_ptr<cli::ProgressBar> bar;
  if (!quiet && cli::progressEnabledByDefault()) {
    options.progress = [&bar](uint64_t done, uint64_t total) {
      if (!bar) bar = std::make_unique<cli::ProgressBar>("merging", total, true, "tiles");
      bar->update(done);
    };
  }
  options.cancel = &g_cancel;
  cli::installSignalHandlers(&g_cancel);

  MergeSummary summary;
  const Status status = mergeShards(options, &summary);
  if (bar) bar->finish();
  if (!status) {
    if (status.code == ErrorCode::kCancelled) {
      std::cerr << "clipstream-merge: stopped by signal " << g_cancel.load() << "; nothing was written\n";
      return cli::kExitSignalBase + g_cancel.load();
    }
    cli::printError(app, status.toString());
    return cli::kExitFailure;
  }
  if (!quiet) {
    std::printf("%u shards -> %s: %llux%llu %s, %u levels (0..%u copied: %llu tiles; %llu built), "
                "output %.1f MB, wall %.2f s\n",
                summary.shards, printableText(options.output_path, 300).c_str(),
                (unsigned long long)summary.width_px, (unsigned long long)summary.height_px,
                pixelFormatName(summary.format), summary.levels, summary.merged_levels - 1,
                (unsigned long long)summary.copied_tiles, (unsigned long long)summary.built_tiles,
                double(summary.output_bytes) / (1024.0 * 1024.0), summary.wall_s);
  }
  return cli::finish(app, cli::kExitOk);
}
