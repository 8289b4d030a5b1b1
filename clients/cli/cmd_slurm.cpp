// `plenopiv slurm submit|status`: a recorded run reprocessed on a Slurm cluster, one array task per
// shard (`plenopiv process --run ... --shard i/n --resume`) and a merge job after them; where the
// settings measure a depth response, a setup job before them (`--prepare`) that keeps it for all.
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "clients/cli/commands.hpp"
#include "clients/cli/reprocess.hpp"
#include "clients/cli/subprocess.hpp"
#include "core/base/errors.hpp"
#include "core/base/yaml_access.hpp"
#include "core/io/atomic_file.hpp"
#include "core/io/checksum.hpp"

namespace plenopiv::client {
namespace {
namespace fs = std::filesystem;

struct SlurmOptions {
  fs::path run;
  fs::path output;
  std::string config;
  std::string tier = "full";
  std::string pairs;
  int shards = 4;
  std::string partition;
  std::string time;  // Slurm's time limit format (minutes, "HH:MM:SS", "D-HH"); empty: the partition's
  int cpus = 2;
  std::string mem;  // Slurm's --mem (e.g. 4G); empty: the estimate for one pair in flight
  bool resume = false;
  bool dry_run = false;
  fs::path program;  // the plenopiv the tasks run; default: this one
  // The jobs' weights cache (`process --cache-dir`); empty: each node's default. The setup job's
  // depth response reaches the tasks only through a folder the nodes share.
  fs::path cache_dir;
};

// The submissions made for an output folder, newest last: <output>/slurm/jobs.yaml.
struct Submission {
  std::string setup_job, array_job, merge_job, time;  // setup_job: empty when there was none
  int shards = 0;
  std::vector<int> tasks;
};

fs::path slurm_dir(const fs::path& output) { return output / "slurm"; }

std::vector<Submission> read_submissions(const fs::path& output) {
  const fs::path file = slurm_dir(output) / "jobs.yaml";
  std::vector<Submission> out;
  if (!fs::exists(file)) return out;
  const YamlMap root(load_yaml_file(file), file.string());
  for (const YAML::Node& n : root.node()["submissions"]) {
    const YamlMap m(n, file.string(), "submissions");
    Submission s;
    s.setup_job = m.string_or("setup_job", "");
    s.array_job = m.string_or("array_job", "");
    s.merge_job = m.string("merge_job");
    s.time = m.string("time");
    s.shards = m.integer_in("shards", 0, 1, 10000);
    for (const YAML::Node& t : n["tasks"]) s.tasks.push_back(t.as<int>());
    out.push_back(s);
  }
  return out;
}

void write_submissions(const fs::path& output, const std::vector<Submission>& submissions) {
  YAML::Emitter e;
  e << YAML::BeginMap << YAML::Key << "submissions" << YAML::Value << YAML::BeginSeq;
  for (const Submission& s : submissions) {
    e << YAML::BeginMap << YAML::Key << "setup_job" << YAML::Value << s.setup_job << YAML::Key << "array_job"
      << YAML::Value << s.array_job << YAML::Key << "merge_job" << YAML::Value << s.merge_job << YAML::Key << "time"
      << YAML::Value << s.time << YAML::Key << "shards" << YAML::Value << s.shards << YAML::Key << "tasks"
      << YAML::Value << YAML::Flow << s.tasks << YAML::EndMap;
  }
  e << YAML::EndSeq << YAML::EndMap;
  io::write_text_atomically(slurm_dir(output) / "jobs.yaml", std::string(e.c_str()) + "\n");
}

// A word for a bash script, single-quoted.
std::string quoted(const std::string& word) {
  std::string out = "'";
  for (char c : word) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

std::string now_utc() {
  const std::time_t t = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return text;
}

std::string this_program() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (ec) throw std::runtime_error("cannot find this program's path (/proc/self/exe): " + ec.message());
  return self.string();
}

// "0-3" or "1,3": the array's task list.
std::string task_list(const std::vector<int>& tasks) {
  bool contiguous = true;
  for (std::size_t i = 1; i < tasks.size(); ++i) contiguous = contiguous && tasks[i] == tasks[i - 1] + 1;
  if (contiguous && tasks.size() > 1) return std::to_string(tasks.front()) + "-" + std::to_string(tasks.back());
  std::string out;
  for (int t : tasks) out += (out.empty() ? "" : ",") + std::to_string(t);
  return out;
}

// The arguments of `plenopiv process --run` every job of a submission shares.
std::vector<std::string> process_arguments(const SlurmOptions& o, const fs::path& run, const fs::path& output,
                                           const std::string& config) {
  std::vector<std::string> args{"process",  "--run", run.string(), "-o",  output.string(),
                                "--config", config,  "--tier",     o.tier};
  if (!o.pairs.empty()) args.insert(args.end(), {"--pairs", o.pairs});
  if (!o.cache_dir.empty()) args.insert(args.end(), {"--cache-dir", fs::absolute(o.cache_dir).string()});
  return args;
}

std::string sbatch_script(const std::string& comment, const std::vector<std::string>& directives,
                          const std::string& program, const std::vector<std::string>& args, const std::string& tail) {
  std::string s = "#!/bin/bash\n# " + comment + " (written by `plenopiv slurm submit`)\n";
  for (const std::string& d : directives) s += "#SBATCH " + d + "\n";
  s += "set -euo pipefail\nexec " + quoted(program);
  for (const std::string& a : args) s += " " + quoted(a);
  return s + tail + "\n";
}

// sbatch --parsable prints "<job id>" or "<job id>;<cluster>".
std::string submit(const std::vector<std::string>& argv) {
  const ProgramResult r = run_program(argv);
  std::string id = r.output.substr(0, r.output.find_first_of(";\n"));
  const bool numeric = !id.empty() && id.find_first_not_of("0123456789") == std::string::npos;
  if (r.exit_code != 0 || !numeric) {
    std::string command;
    for (const std::string& a : argv) command += (command.empty() ? "" : " ") + a;
    throw InputError("sbatch refused the job (exit " + std::to_string(r.exit_code) + "): " + command + ": " + r.output);
  }
  return id;
}

// squeue's lines for these jobs ("<id> <state> <reason>"), none when Slurm no longer knows them.
std::vector<std::string> queued(const std::vector<std::string>& jobs) {
  std::string ids;
  for (const std::string& j : jobs) {
    if (!j.empty()) ids += (ids.empty() ? "" : ",") + j;
  }
  if (ids.empty()) return {};
  const ProgramResult r = run_program({"squeue", "--noheader", "--jobs=" + ids, "--format=%i %T %r"});
  if (r.exit_code != 0) {
    if (r.output.find("Invalid job id") != std::string::npos) return {};  // all of them finished long ago
    throw InputError("squeue failed (exit " + std::to_string(r.exit_code) + "): " + r.output);
  }
  std::vector<std::string> lines;
  std::istringstream in(r.output);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) lines.push_back(line);
  }
  return lines;
}

bool is_array_task_of(const std::string& line, const std::string& array_job) {
  return !array_job.empty() && line.rfind(array_job + "_", 0) == 0;
}

// Whether squeue's job id `id` ("123_4", or pending tasks as "123_[1-3,5%2]") names task `task` of
// array job `array_job`.
bool names_task(const std::string& id, const std::string& array_job, int task) {
  if (!is_array_task_of(id, array_job)) return false;
  std::string tasks = id.substr(array_job.size() + 1);
  if (tasks.empty()) return false;
  if (tasks.front() != '[') return tasks == std::to_string(task);
  tasks = tasks.substr(1, tasks.find_first_of("%]") - 1);
  std::istringstream in(tasks);
  for (std::string part; std::getline(in, part, ',');) {
    const std::size_t dash = part.find('-');
    try {
      const int lo = std::stoi(part.substr(0, dash));
      const int hi = dash == std::string::npos ? lo : std::stoi(part.substr(dash + 1));
      if (task >= lo && task <= hi) return true;
    } catch (const std::exception&) {
      return false;  // not a task list this code knows: the shard's own outputs speak for it
    }
  }
  return false;
}

ReprocessOptions reprocess_options(const SlurmOptions& o) {
  ReprocessOptions r;
  r.run = fs::absolute(o.run).lexically_normal();
  r.output = o.output.empty() ? r.run / "reprocessed" : fs::absolute(o.output).lexically_normal();
  r.config = o.config;
  r.tier = o.tier;
  if (!o.pairs.empty()) r.pairs = parse_pair_range(o.pairs);
  return r;
}

void run_submit(const SlurmOptions& o) {
  if (o.shards < 1 || o.shards > 10000) throw InputError("--shards: 1 to 10000, got " + std::to_string(o.shards));
  if (o.cpus < 1 || o.cpus > 1024) throw InputError("--cpus: 1 to 1024, got " + std::to_string(o.cpus));
  const ReprocessOptions r = reprocess_options(o);
  // Checks the folder, its frames and the settings now, on this machine, not in a queued job.
  std::fprintf(stderr, "%s: checking the run%s ...\n", r.run.string().c_str(),
               o.resume ? " and which pairs are done (reads every frame)" : "");
  const ShardPlan plan = plan_shards(r, o.shards, o.resume);
  std::vector<int> tasks;
  std::size_t pairs = 0;
  for (const ShardState& s : plan.shards) pairs += s.pairs;
  if (pairs < std::size_t(o.shards))
    throw InputError("--shards " + std::to_string(o.shards) + ": only " + std::to_string(pairs) +
                     " pairs are selected; use at most as many shards as pairs");
  for (int i = 0; i < o.shards; ++i) {
    if (!o.resume || !plan.shards[std::size_t(i)].complete()) tasks.push_back(i);
  }
  const std::vector<Submission> before = read_submissions(r.output);
  if (o.resume && !o.dry_run) {
    // A resubmission must not race tasks of an earlier one still queued or running.
    for (const Submission& s : before) {
      for (const std::string& line : queued({s.setup_job, s.array_job})) {
        throw InputError("job " + line.substr(0, line.find(' ')) + " (an earlier submission for " + r.output.string() +
                         ") is still in the queue: '" + line + "'; wait for it or scancel it, then --resume");
      }
      if (!queued({s.merge_job}).empty()) {
        const ProgramResult c = run_program({"scancel", s.merge_job});
        std::fprintf(stderr, "earlier merge job %s cancelled (it waited on failed tasks)%s\n", s.merge_job.c_str(),
                     c.exit_code == 0 ? "" : (": scancel: " + c.output).c_str());
      }
    }
  }

  const fs::path dir = slurm_dir(r.output);
  fs::create_directories(dir);
  // The settings the jobs use, frozen at submission (a later edit of the file changes nothing queued).
  std::string config = "run";
  if (!o.config.empty() && o.config != "run") {
    config = (dir / "process.yaml").string();
    io::write_text_atomically(config, io::read_file_bytes(o.config));
  }
  const std::string program = o.program.empty() ? this_program() : fs::absolute(o.program).string();
  const double mem_mb = std::ceil(plan.bytes_per_pair * 1.25 / 1e6) + 512;  // a quarter and half a GB of margin
  const std::string mem = o.mem.empty() ? std::to_string(long(mem_mb)) + "M" : o.mem;
  const std::string name = "plenopiv-" + r.run.filename().string();
  std::vector<std::string> common{"--job-name=" + name, "--mem=" + mem};
  if (!o.partition.empty()) common.push_back("--partition=" + o.partition);
  if (!o.time.empty()) common.push_back("--time=" + o.time);
  // A job's directives: the common ones, its CPUs and its log in slurm/.
  const auto directives = [&](int cpus, const std::string& log) {
    std::vector<std::string> d = common;
    d.push_back("--cpus-per-task=" + std::to_string(cpus));
    d.push_back("--output=" + (dir / log).string());
    return d;
  };

  const std::vector<std::string> args = process_arguments(o, r.run, r.output, config);
  std::vector<std::string> shard_args = args;
  shard_args.insert(shard_args.end(), {"--resume", "--threads", std::to_string(o.cpus), "--shard"});
  const std::string shard_script =
      sbatch_script("plenopiv: shard ${SLURM_ARRAY_TASK_ID} of " + std::to_string(o.shards) + " of " + r.run.string(),
                    directives(o.cpus, "shard-%a.out"), program, shard_args,
                    " \"${SLURM_ARRAY_TASK_ID}/" + std::to_string(o.shards) + "\"");
  std::vector<std::string> merge_args = args;
  merge_args.push_back("--merge");
  const std::string merge_script =
      sbatch_script("plenopiv: merge of " + r.run.string(), directives(1, "merge.out"), program, merge_args, "");
  io::write_text_atomically(dir / "shards.sbatch", shard_script);
  io::write_text_atomically(dir / "merge.sbatch", merge_script);
  // The depth response is measured once, by a job the shards wait for, not by every shard at once.
  const bool setup = plan.depth_response && !tasks.empty();
  if (setup) {
    std::vector<std::string> setup_args = args;
    setup_args.insert(setup_args.end(), {"--prepare", "--threads", std::to_string(o.cpus)});
    io::write_text_atomically(dir / "setup.sbatch",
                              sbatch_script("plenopiv: weight tables and depth response for " + r.run.string(),
                                            directives(o.cpus, "setup.out"), program, setup_args, ""));
  }

  std::fprintf(stderr, "%zu pairs in %d shards; %zu shard(s) to run: %s; %.2f GB per pair in flight, --mem=%s\n", pairs,
               o.shards, tasks.size(), tasks.empty() ? "none" : task_list(tasks).c_str(), plan.bytes_per_pair / 1e9,
               mem.c_str());
  std::vector<std::string> setup_command{"sbatch", "--parsable", (dir / "setup.sbatch").string()};
  std::vector<std::string> array_command{"sbatch", "--parsable", "--array=" + task_list(tasks),
                                         (dir / "shards.sbatch").string()};
  std::vector<std::string> merge_command{"sbatch", "--parsable", "--kill-on-invalid-dep=yes",
                                         (dir / "merge.sbatch").string()};
  if (o.dry_run) {
    if (setup) std::cout << (dir / "setup.sbatch").string() << "\n";
    std::cout << (dir / "shards.sbatch").string() << "\n" << (dir / "merge.sbatch").string() << "\n";
    return;
  }
  Submission s;
  s.shards = o.shards;
  s.tasks = tasks;
  s.time = now_utc();
  if (setup) {
    s.setup_job = submit(setup_command);
    array_command.insert(array_command.begin() + 2,
                         {"--dependency=afterok:" + s.setup_job, "--kill-on-invalid-dep=yes"});
  }
  if (!tasks.empty()) {
    s.array_job = submit(array_command);
    merge_command.insert(merge_command.begin() + 2, "--dependency=afterok:" + s.array_job);
  }
  s.merge_job = submit(merge_command);
  std::vector<Submission> all = before;
  all.push_back(s);
  write_submissions(r.output, all);
  std::fprintf(
      stderr, "submitted: %sarray job %s (tasks %s), merge job %s after it; `plenopiv slurm status --run %s%s`\n",
      s.setup_job.empty() ? "" : ("setup job " + s.setup_job + " (depth response), ").c_str(),
      s.array_job.empty() ? "none" : s.array_job.c_str(), tasks.empty() ? "none" : task_list(tasks).c_str(),
      s.merge_job.c_str(), r.run.string().c_str(), o.output.empty() ? "" : (" -o " + r.output.string()).c_str());
  std::cout << s.array_job << " " << s.merge_job << "\n";
}

void run_status(const SlurmOptions& o) {
  const ReprocessOptions r = reprocess_options(o);
  const std::vector<Submission> submissions = read_submissions(r.output);
  if (submissions.empty())
    throw InputError(r.output.string() +
                     ": no Slurm submission recorded (slurm/jobs.yaml); `plenopiv slurm submit` first");
  const Submission& last = submissions.back();
  const ShardPlan plan = plan_shards(r, last.shards, false);
  const std::vector<std::string> lines = queued({last.setup_job, last.array_job, last.merge_job});
  std::size_t pairs = 0, done = 0;
  for (const ShardState& s : plan.shards) {
    pairs += s.pairs;
    done += s.done;
  }
  std::printf("run        %s\noutput     %s\nsubmitted  %s: array job %s (tasks %s), merge job %s\n",
              r.run.string().c_str(), r.output.string().c_str(), last.time.c_str(),
              last.array_job.empty() ? "none" : last.array_job.c_str(), task_list(last.tasks).c_str(),
              last.merge_job.c_str());
  if (!last.setup_job.empty()) {
    // Out of the queue it has finished: its log says how (a failed one takes its tasks with it).
    std::string state = "finished (slurm/setup.out)";
    for (const std::string& line : lines) {
      if (line.rfind(last.setup_job + " ", 0) == 0) state = line.substr(line.find(' ') + 1);
    }
    std::printf("setup      job %s: %s\n", last.setup_job.c_str(), state.c_str());
  }
  std::printf("pairs      %zu of %zu have outputs (%.0f %%)\n", done, pairs,
              pairs ? 100.0 * double(done) / double(pairs) : 0.0);
  std::size_t incomplete = 0;
  for (std::size_t i = 0; i < plan.shards.size(); ++i) {
    const ShardState& s = plan.shards[i];
    std::string state;
    for (const std::string& line : lines) {
      if (names_task(line.substr(0, line.find(' ')), last.array_job, int(i))) state = line.substr(line.find(' ') + 1);
    }
    if (state.empty())
      state =
          s.complete() ? "done" : "not in the queue: failed or cancelled (slurm/shard-" + std::to_string(i) + ".out)";
    if (!s.complete()) ++incomplete;
    std::printf("shard %-4zu %zu/%zu  %s\n", i, s.done, s.pairs, state.c_str());
  }
  std::string merge_state = plan.merged ? "done: statistics.h5, series.pvd" : "";
  for (const std::string& line : lines) {
    if (line.rfind(last.merge_job + " ", 0) == 0) merge_state = line.substr(line.find(' ') + 1);
  }
  if (merge_state.empty()) merge_state = "not in the queue and not done (slurm/merge.out)";
  std::printf("merge      %s\n", merge_state.c_str());
  bool array_queued = false;
  for (const std::string& line : lines) array_queued = array_queued || is_array_task_of(line, last.array_job);
  if (incomplete > 0 && !array_queued)
    std::printf("next       plenopiv slurm submit --run %s%s --resume   (resubmits the %zu incomplete shard(s))\n",
                r.run.string().c_str(), o.output.empty() ? "" : (" -o " + r.output.string()).c_str(), incomplete);
}

}  // namespace

void add_slurm_commands(CLI::App& app) {
  auto o = std::make_shared<SlurmOptions>();
  auto* slurm = app.add_subcommand("slurm", "reprocess a recorded run on a Slurm cluster (array job + merge)");
  slurm->require_subcommand(1);
  auto* submit_cmd = slurm->add_subcommand(
      "submit", "write an sbatch array script (one task per shard) and a merge job after it, and submit both");
  auto* status_cmd = slurm->add_subcommand("status", "progress of a submission: pairs done per shard, squeue");
  for (CLI::App* cmd : {submit_cmd, status_cmd}) {
    cmd->add_option("--run", o->run, "the run folder (plenopivd's), on a file system the nodes share")->required();
    cmd->add_option("-o,--output", o->output, "output folder (default <run>/reprocessed)");
    cmd->add_option("--pairs", o->pairs, "pair indices a:b (b excluded; a: or :b)");
  }
  submit_cmd->add_option("-c,--config", o->config,
                         "processing spec YAML (offline settings), or 'run' for the run's own (the default)");
  submit_cmd->add_option("--tier", o->tier, "full or live")->capture_default_str();
  submit_cmd->add_option("--shards", o->shards, "array tasks; each processes a contiguous block of pairs")
      ->capture_default_str();
  submit_cmd->add_option("--partition", o->partition, "Slurm partition (default: the cluster's)");
  submit_cmd->add_option("--time", o->time, "time limit per task, Slurm's format (e.g. 2:00:00)");
  submit_cmd->add_option("--cpus", o->cpus, "CPUs per task (the task's --threads)")->capture_default_str();
  submit_cmd->add_option("--mem", o->mem, "memory per task, Slurm's format (default: one pair's estimate + margin)");
  submit_cmd->add_flag("--resume", o->resume,
                       "submit only the shards with pairs not done (after failed tasks), and the merge");
  submit_cmd->add_flag("--dry-run", o->dry_run, "write the sbatch scripts and print their paths; submit nothing");
  submit_cmd->add_option("--plenopiv", o->program, "the plenopiv the jobs run (default: this one)");
  submit_cmd->add_option("--cache-dir", o->cache_dir,
                         "the jobs' weights cache folder (process --cache-dir), on a file system the nodes share "
                         "(default: each node's $PLENOPIV_CACHE_DIR, $XDG_CACHE_HOME/plenopiv or ~/.cache/plenopiv)");
  submit_cmd->callback([o] { run_submit(*o); });
  status_cmd->callback([o] { run_status(*o); });
}

}  // namespace plenopiv::client
