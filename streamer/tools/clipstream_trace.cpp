// clipstream-trace: replays a request trace recorded by the streamer
// (StreamerConfig::trace_path) and prints the RAM hit rate of Belady's OPT,
// plain LRU and the streamer's plan-aware eviction at one budget.
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>

#include <clipstream/cli/cli.h>

#include <cstdio>

int main(int argc, char** argv) {
  namespace cli = clipstream::cli;
  CLI::App app{"Replay a clipstream request trace against cache policies", "clipstream-trace"};
  std::string trace_path;
  double budget_mb = 256.0;
  uint64_t tile_bytes = 128 * 128 * 4;
  app.add_option("trace", trace_path, "trace file written by the streamer")->required();
  app.add_option("--budget-mb", budget_mb, "RAM budget in MiB")
      ->required()
      ->transform(cli::inRange(0.001, 16.0 * 1024 * 1024));
  app.add_option("--tile-bytes", tile_bytes, "decoded bytes per tile")
      ->transform(cli::wholeInRange(1, int64_t(1) << 30));
  app.footer("Exit codes: 0 success, 1 the trace cannot be read or is damaged, 2 command-line mistake.");
  if (std::optional<int> code = cli::parse(app, argc, argv)) return *code;
  cli::installSignalHandlers();

  std::vector<clipstream::TraceEvent> events;
  const clipstream::Status status = clipstream::readTrace(trace_path, &events);
  if (!status) {
    cli::printError(app, status.toString());
    return cli::kExitFailure;
  }
  // Same accounting as the streamer: payload plus a fixed per-entry overhead.
  const uint64_t entry_bytes = tile_bytes + clipstream::kCacheEntryOverheadBytes;
  const uint64_t capacity = uint64_t(budget_mb * 1024.0 * 1024.0) / entry_bytes;
  const clipstream::ReplayResult r = clipstream::replayTrace(events, capacity);
  std::printf("# %s: %llu accesses (%llu more entries the GPU serves), %llu distinct tiles, "
              "budget %.1f MiB = %llu tiles of %llu B\n",
              clipstream::printableText(trace_path, 300).c_str(), (unsigned long long)r.accesses,
              (unsigned long long)r.gpu_reentries, (unsigned long long)r.distinct_tiles, budget_mb,
              (unsigned long long)capacity,
              (unsigned long long)entry_bytes);
  std::printf("policy\thits\thit_rate_%%\tof_opt_%%\n");
  auto row = [&](const char* name, uint64_t hits) {
    const double rate = r.accesses ? 100.0 * double(hits) / double(r.accesses) : 0.0;
    const double of_opt = r.hits_opt ? 100.0 * double(hits) / double(r.hits_opt) : 100.0;
    std::printf("%s\t%llu\t%.2f\t%.1f\n", name, (unsigned long long)hits, rate, of_opt);
  };
  row("opt", r.hits_opt);
  row("lru", r.hits_lru);
  row("ours", r.hits_gpu_first);           // default: EvictionMode::kGpuFirst
  row("ours_protect_gpu", r.hits_plan);    // EvictionMode::kProtectGpu
  return cli::finish(app, cli::kExitOk);
}
