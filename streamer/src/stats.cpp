// Stats as JSON (nlohmann builds it, so the output always parses).
#include <clipstream/streamer/stats.h>

#include <nlohmann/json.hpp>

#include <cmath>

namespace clipstream {
namespace {

nlohmann::json countersJson(const LevelCounters& c) {
  return {{"requests", c.requests},       {"ram_hits", c.ram_hits},
          {"ram_misses", c.ram_misses},   {"gpu_reentries", c.gpu_reentries},
          {"gpu_handoffs", c.gpu_handoffs},
          {"cancellations", c.cancellations}, {"evictions", c.evictions},
          {"redundant_reads", c.redundant_reads}, {"bytes_read", c.bytes_read},
          {"failures", c.failures},       {"loads", c.loads},
          {"budget_skips", c.budget_skips}};
}

double finite(double v) { return std::isfinite(v) ? v : 0.0; }

}  // namespace

std::string StreamerStats::toJson() const {
  nlohmann::json j;
  j["total"] = countersJson(total);
  j["levels"] = nlohmann::json::array();
  for (const LevelCounters& c : levels) j["levels"].push_back(countersJson(c));
  j["ram_bytes"] = ram_bytes;
  j["ram_budget_bytes"] = ram_budget_bytes;
  j["ram_peak_bytes"] = ram_peak_bytes;
  j["ram_entries"] = ram_entries;
  j["entry_overhead_bytes"] = entry_overhead_bytes;
  j["queue_depth"] = queue_depth;
  j["in_flight"] = in_flight;
  j["reads_held"] = reads_held;
  j["decode_ms_total"] = finite(decode_ms_total);
  j["queue_latency_p50_ms"] = finite(queue_latency_p50_ms);
  j["queue_latency_p99_ms"] = finite(queue_latency_p99_ms);
  j["max_texture_lod"] = max_texture_lod;
  j["path_hint_frames"] = path_hint_frames;
  j["path_hint_ignored_frames"] = path_hint_ignored_frames;
  j["loader_threads"] = loader_threads;
  j["layers"] = nlohmann::json::array();
  for (const LayerStats& layer : layers) {
    nlohmann::json l;
    l["total"] = countersJson(layer.total);
    l["levels"] = nlohmann::json::array();
    for (const LevelCounters& c : layer.levels) l["levels"].push_back(countersJson(c));
    l["ram_bytes"] = layer.ram_bytes;
    l["ram_entries"] = layer.ram_entries;
    l["max_texture_lod"] = layer.max_texture_lod;
    j["layers"].push_back(std::move(l));
  }
  return j.dump();
}

}  // namespace clipstream
