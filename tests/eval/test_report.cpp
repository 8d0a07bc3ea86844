// The report formats on runs written by hand (no GL): the streamer's
// settings as the reports name them, and the stability scenarios' line with
// the keys scripts/sweep.sh reads.
#include <clipstream/eval/report.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <string>

namespace clipstream {
namespace {

// summary.tsv's value under `key` (one header line, one value line).
std::string tsvValue(const std::string& tsv, const std::string& key) {
  const size_t split = tsv.find('\n');
  const std::string keys = "\t" + tsv.substr(0, split) + "\t";
  const size_t at = keys.find("\t" + key + "\t");
  if (at == std::string::npos) return "(none)";
  size_t column = 0;
  for (size_t i = 0; i < at; ++i) column += keys[i] == '\t';
  std::string values = tsv.substr(split + 1);
  values = values.substr(0, values.find('\n'));
  size_t from = 0;
  for (size_t c = 0; c < column; ++c) from = values.find('\t', from) + 1;
  return values.substr(from, values.find('\t', from) - from);
}

TEST(Report, NamesTheStreamerSettingsOfTheRun) {
  FlightRun run;
  RunDescription d;
  d.streamer.ram_budget_bytes = uint64_t(64) << 20;
  d.streamer.throttle = false;
  d.streamer.planner.scope = PlanScope::kWindow;
  d.streamer.deterministic_io = {true, 4, 3};
  std::string tsv = summaryTsv(run, d);
  EXPECT_EQ(tsvValue(tsv, "cache_mb"), "64");
  EXPECT_EQ(tsvValue(tsv, "io_mode"), "deterministic");
  EXPECT_EQ(tsvValue(tsv, "io_reads_per_frame"), "4");
  EXPECT_EQ(tsvValue(tsv, "io_latency_frames"), "3");
  nlohmann::json acc = nlohmann::json::parse(framesJson(run, d))["summary"]["accuracy"];
  EXPECT_EQ(acc["cache_mb"], 64);
  EXPECT_EQ(acc["throttle"], false);
  EXPECT_EQ(acc["prefetch"], true);
  EXPECT_EQ(acc["plan_scope"], "window");
  EXPECT_EQ(acc["io_reads_per_frame"], 4);

  // In real time the deterministic clock's settings do not count.
  d.streamer.deterministic_io.enabled = false;
  tsv = summaryTsv(run, d);
  EXPECT_EQ(tsvValue(tsv, "io_mode"), "real-time");
  EXPECT_EQ(tsvValue(tsv, "io_reads_per_frame"), "0");
  acc = nlohmann::json::parse(framesJson(run, d))["summary"]["accuracy"];
  EXPECT_EQ(acc["io_latency_frames"], 0);
  EXPECT_EQ(acc["plan_scope"], "window");
}

TEST(Report, ScenarioLineCarriesTheStabilityTableKeys) {
  FlightRun run;
  run.frames.resize(6);
  run.frames[2].accuracy.measured = true;  // a moving frame: not a rest frame
  run.frames[3].accuracy.measured = true;
  run.frames[3].accuracy.error.max_abs_error = 2;
  run.frames[5].accuracy.measured = true;
  run.frames[5].accuracy.error.max_abs_error = 0;
  run.streamer.ram_peak_bytes = 3 << 20;
  run.streamer.ram_budget_bytes = 8 << 20;
  run.render_thread_fetches = 1;
  run.rss_after_warmup_bytes = 100;
  run.rss_end_bytes = 200;
  run.garbage_checked_frames = 2;
  run.garbage_pixels_max = 7;
  EXPECT_EQ(restFramesToIdentical(run, 3), 2);
  EXPECT_EQ(restFramesToIdentical(run, 6), -1);

  const std::string line = scenarioJsonLine(run, {"speed x100", 3, 3, false});
  // One line, compact: the sweep reads it with sed, "key":value.
  ASSERT_FALSE(line.empty());
  EXPECT_EQ(line.find('\n'), line.size() - 1);
  EXPECT_EQ(line.find("\": "), std::string::npos);
  const nlohmann::json j = nlohmann::json::parse(line);
  EXPECT_EQ(j["scenario"], "speed x100");
  EXPECT_EQ(j["moving_frames"], 3);
  EXPECT_EQ(j["rest_frames"], 3);
  EXPECT_EQ(j["rest_frames_to_identical"], 2);
  EXPECT_EQ(j["render_thread_fetches"], 1);
  EXPECT_EQ(j["ram_peak_bytes"], 3 << 20);
  EXPECT_EQ(j["ram_budget_bytes"], 8 << 20);
  EXPECT_EQ(j["rss_after_warmup_bytes"], 100);
  EXPECT_EQ(j["rss_end_bytes"], 200);
  EXPECT_EQ(j["garbage_checked_frames"], 2);
  EXPECT_EQ(j["garbage_pixels_max"], 7);
  EXPECT_EQ(j["result"], "FAIL");
  // The run's summary (RunSummary::toJson()) is merged in.
  for (const char* key : {"frames", "psnr_min_db", "psnr_mean_db", "time_to_sharp_max", "frame_ms_p99"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(nlohmann::json::parse(scenarioJsonLine(run, {"x", 6, 0, true}))["result"], "pass");
  EXPECT_EQ(nlohmann::json::parse(scenarioJsonLine(run, {"x", 6, 0, true}))["rest_frames_to_identical"], -1);
}

}  // namespace
}  // namespace clipstream
