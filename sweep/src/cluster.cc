#include "evio/sweep/cluster.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "evio/calib/error.h"
#include "evio/calib/json.h"
#include "evio/sweep/results.h"

namespace evio::sweep {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

// Whether `program` is found on PATH (or is a path that exists).
bool on_path(const std::string& program) {
  if (program.find('/') != std::string::npos) return access(program.c_str(), X_OK) == 0;
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "/usr/bin:/bin");
  std::string d;
  while (std::getline(dirs, d, ':')) {
    if (!d.empty() && access((d + "/" + program).c_str(), X_OK) == 0) return true;
  }
  return false;
}

// Runs a shell command line, returns its stdout+stderr and sets *status to its exit code (-1: not run).
std::string capture(const std::string& command, int* status) {
  std::string out;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (!p) {
    *status = -1;
    return out;
  }
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int st = pclose(p);
  *status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return out;
}

void append_to(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::app);
  f << text;
}

void write_atomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp" + std::to_string(getpid());
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << text;
    if (!f.flush()) throw std::runtime_error(tmp + ": write failed");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) throw std::runtime_error(path + ": rename failed: " + std::strerror(errno));
}

}  // namespace

SweepOutcome sweep_outcome_without_file(const SweepJob& job, int exit_code, double wall_s, const std::string& host, const std::string& why) {
  SweepOutcome o;
  o.exit_code = exit_code != 0 ? exit_code : 125;  // never a success: nothing was measured
  o.wall_s = wall_s;
  o.cpu_s = NAN;
  o.peak_rss_mb = NAN;
  o.host = host;
  append_to(job.stderr_path, "evio sweep: the job's runner left no " + sweep_outcome_path(job) + ": " + why + "\n");
  return o;
}

namespace {

bool read_outcome(const SweepJob& job, SweepOutcome* o) { return parse_sweep_outcome(sweep_read_file(sweep_outcome_path(job)), o); }

// The first runN stem in folder whose files do not exist yet (the runs of a sweep are kept).
std::string next_run_stem(const fs::path& folder) {
  std::error_code ec;
  for (int k = 1;; ++k) {
    const std::string stem = "run" + std::to_string(k);
    if (!fs::exists(folder / (stem + ".jobs"), ec)) return (folder / stem).string();
  }
}

// A path relative to the sweep folder when it is inside it (a/b), the path otherwise.
std::string inside(const std::string& path, const std::string& dir) {
  const std::string prefix = dir + "/";
  return path.compare(0, prefix.size(), prefix) == 0 ? path.substr(prefix.size()) : path;
}

std::string command_of(const std::string& runner, const std::vector<std::string>& args) {
  std::string s = sweep_shell_quote(runner);
  for (const std::string& a : args) s += " " + sweep_shell_quote(a);
  return s;
}

// A process started with its own process group, in folder `cwd`, stdin from /dev/null and
// stdout+stderr to `log`; it gets SIGTERM when the sweep dies.
pid_t start_process(const std::vector<std::string>& argv_s, const std::string& cwd, const std::string& log) {
  std::vector<char*> argv;
  for (const std::string& a : argv_s) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(127);
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
    for (int sig : {SIGINT, SIGTERM, SIGPIPE}) signal(sig, SIG_DFL);
    const int in = open("/dev/null", O_RDONLY);
    const int out = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (in < 0 || out < 0 || chdir(cwd.c_str()) != 0) _exit(127);
    dup2(in, 0);
    dup2(out, 1);
    dup2(out, 2);
    execvp(argv[0], argv.data());
    _exit(127);
  }
  if (pid > 0) setpgid(pid, pid);
  return pid;
}

// Ends a started process: waits up to wait_s for it to end, then SIGTERM (GNU parallel then kills
// its jobs), SIGKILL to its group after 5 s more.
void stop_process(pid_t pid, double wait_s = 0) {
  for (int i = 0; i < wait_s * 50; ++i) {
    if (waitpid(pid, nullptr, WNOHANG) == pid) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(pid, SIGTERM);
  for (int i = 0; i < 250; ++i) {
    if (waitpid(pid, nullptr, WNOHANG) == pid) {
      kill(-pid, SIGKILL);
      return;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(-pid, SIGKILL);
  waitpid(pid, nullptr, 0);
}

void check_fields(const SweepJob& job, const std::string& line) {
  if (line.find('\n') != std::string::npos || std::count(line.begin(), line.end(), '\t') != 1) {
    throw InputError(job.stdout_path, 0, "a job's paths or arguments contain a tab or a newline", "arguments without tabs or newlines for --engine parallel");
  }
}

// The job with its program and the arguments that name existing files by a relative path (a spec
// given by a relative path gives such dataset paths) made absolute: parallel and slurm run the
// runner in DIR, not in this process's folder.
SweepJob with_absolute_paths(SweepJob j) {
  std::error_code ec;
  if (!j.program.empty() && j.program[0] != '/') j.program = fs::absolute(j.program).lexically_normal().string();
  for (std::string& a : j.args) {
    if (!a.empty() && a[0] != '/' && a[0] != '-' && fs::exists(a, ec)) a = fs::absolute(a).lexically_normal().string();
  }
  return j;
}

// The folder (relative to DIR) that holds every path a job writes, returned in one transfer:
// DIR/cells/<cell>/ for a cell (its logs, outcome.json and out/).
std::string returned_folder(const std::vector<std::string>& paths) {
  fs::path common;
  bool first = true;
  for (const std::string& p : paths) {
    if (p.empty()) continue;
    const fs::path folder = &p == &paths.back() ? fs::path(p) : fs::path(p).parent_path();  // the last one: the output folder itself
    if (first) {
      common = folder;
      first = false;
      continue;
    }
    fs::path c;
    for (auto a = common.begin(), b = folder.begin(); a != common.end() && b != folder.end() && *a == *b; ++a, ++b) c /= *a;
    common = c;
  }
  return common.empty() ? std::string(".") : common.string();
}

class ParallelEngine : public SweepEngine {
 public:
  explicit ParallelEngine(const SweepEngineOptions& o) : o_(o) {
    if (!on_path("parallel")) {
      throw std::invalid_argument("--engine parallel: GNU parallel is not installed (Debian: apt-get install parallel)");
    }
    if (!o_.hosts.empty() && !on_path("rsync")) {
      throw std::invalid_argument("--engine parallel --hosts: rsync is not installed (Debian: apt-get install rsync)");
    }
    if (o_.runner.empty()) o_.runner = sweep_self_program();
    o_.dir = fs::absolute(o_.dir).lexically_normal().string();
    while (o_.dir.size() > 1 && o_.dir.back() == '/') o_.dir.pop_back();
  }
  std::string name() const override { return "parallel"; }

  void run(const std::vector<SweepJob>& jobs, const std::function<void(size_t, const SweepOutcome&)>& done) override {
    if (jobs.empty()) return;
    const fs::path pdir = fs::path(o_.dir) / "parallel";
    fs::create_directories(pdir);
    const std::string stem = next_run_stem(pdir);
    const bool remote = !o_.hosts.empty();
    std::set<std::string> basefiles;
    std::string runner = o_.runner;
    std::map<std::string, std::string> shipped;  // program -> parallel/bin/<name>
    if (remote) {
      fs::create_directories(pdir / "bin");
      runner = ship_program(o_.runner, &shipped);
      if (ship_plugins()) basefiles.insert("parallel/lib");
    }
    std::ostringstream lines;
    for (const SweepJob& job : jobs) {
      SweepJob j = with_absolute_paths(job);
      for (std::string* p : {&j.stdout_path, &j.stderr_path, &j.out_dir}) *p = inside(*p, o_.dir);
      for (std::string& a : j.args) {
        std::error_code ec;
        if (remote && a.size() > 1 && a[0] == '/' && a.rfind(o_.dir + "/", 0) != 0 && fs::exists(a, ec)) basefiles.insert(a);
        a = inside(a, o_.dir);
        if (remote && !a.empty() && a[0] != '/' && fs::exists(fs::path(o_.dir) / a, ec) && a.rfind("cells/", 0) != 0) basefiles.insert(a);
      }
      j.program = remote ? ship_program(j.program, &shipped) : j.program;
      std::error_code ec;
      fs::remove(sweep_outcome_path(job), ec);  // a stale outcome of an earlier run is not this run's
      const std::string outcome = inside(sweep_outcome_path(job), o_.dir);
      const std::string line = returned_folder({j.stdout_path, j.stderr_path, outcome, j.out_dir}) + "\t" + command_of(runner, run_cell_arguments(j));
      check_fields(job, line);
      lines << line << "\n";
    }
    sweep_write_file(stem + ".jobs", lines.str());
    std::vector<std::string> argv = {"parallel", "--will-cite", "--colsep", "\t", "--joblog", stem + ".joblog", "-a", stem + ".jobs",
                                     "--jobs", o_.jobs > 0 ? std::to_string(o_.jobs) : "100%"};
    if (remote) {
      // No --cleanup: it would also delete the basefiles sent to their absolute paths (on a host that
      // is this machine: the originals); the work dir is removed below instead.
      argv.insert(argv.end(), {"--sshloginfile", fs::absolute(o_.hosts).string(), "--workdir", remote_workdir()});
      for (const auto& [program, copy] : shipped) argv.insert(argv.end(), {"--basefile", copy});
      for (const std::string& b : basefiles) argv.insert(argv.end(), {"--basefile", b});
      argv.insert(argv.end(), {"--return", "{1}"});
    }
    argv.push_back("eval {2}");
    const std::string log = stem + ".log";
    const pid_t pid = start_process(argv, o_.dir, log);
    std::vector<bool> reported(jobs.size(), false);
    size_t seen = 0;  // joblog entries handled
    bool exited = false;
    int status = 0;
    const auto start = Clock::now();
    while (true) {
      if (sweep_stop_requested()) {
        stop_process(pid);
        return;
      }
      if (!exited && waitpid(pid, &status, WNOHANG) == pid) exited = true;
      const std::vector<ParallelJoblogEntry> entries = parse_parallel_joblog(sweep_read_file(stem + ".joblog"));
      for (; seen < entries.size(); ++seen) {
        const ParallelJoblogEntry& e = entries[seen];
        if (e.seq < 1 || e.seq > jobs.size() || reported[e.seq - 1]) continue;
        const size_t i = e.seq - 1;
        SweepOutcome o;
        if (!read_outcome(jobs[i], &o)) {
          o = sweep_outcome_without_file(jobs[i], e.signal ? -e.signal : e.exit_value, e.runtime_s, e.host,
                                   "GNU parallel's joblog says exit value " + std::to_string(e.exit_value) + ", signal " + std::to_string(e.signal) +
                                       " (its messages: " + log + ")");
        }
        if (remote) o.host = e.host;
        reported[i] = true;
        done(i, o);
      }
      if (exited) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (remote) {  // the copies of the programs, data and cell folders on the hosts
      stop_process(start_process({"parallel", "--will-cite", "--nonall", "--sshloginfile", fs::absolute(o_.hosts).string(),
                                  "rm -rf " + remote_workdir()},
                                 o_.dir, stem + ".cleanup.log"),
                   120);
    }
    // Jobs GNU parallel never logged (it failed, or was killed): reported, not lost.
    const double s = std::chrono::duration<double>(Clock::now() - start).count();
    for (size_t i = 0; i < jobs.size(); ++i) {
      if (reported[i]) continue;
      SweepOutcome o;
      if (!read_outcome(jobs[i], &o)) {
        o = sweep_outcome_without_file(jobs[i], 127, s, remote ? "" : sweep_hostname(),
                                 "GNU parallel ended (" + std::string(WIFEXITED(status) ? "exit code " + std::to_string(WEXITSTATUS(status))
                                                                                       : "signal " + std::to_string(WTERMSIG(status))) +
                                     ") without running it; its messages: " + log);
      }
      done(i, o);
    }
  }

 private:
  // The copy of a program in DIR/parallel/bin/ (sent once per host), as a path relative to DIR.
  std::string ship_program(const std::string& program, std::map<std::string, std::string>* shipped) {
    auto it = shipped->find(program);
    if (it != shipped->end()) return it->second;
    const std::string rel = "parallel/bin/" + fs::path(program).filename().string();
    link_or_copy(program, fs::path(o_.dir) / rel);
    (*shipped)[program] = rel;
    return rel;
  }

  // evio's plugins (calib/plugin.h) next to the shipped programs, in DIR/parallel/lib/evio/ (where a
  // program in DIR/parallel/bin/ looks first): from $EVIO_PLUGIN_DIR, else from where the runner's
  // own programs find them (<its folder>/../lib/evio, <its folder>/../../lib/evio). False: none found.
  bool ship_plugins() {
    const fs::path exe = fs::path(o_.runner).parent_path();
    std::vector<fs::path> dirs;
    if (const char* env = std::getenv("EVIO_PLUGIN_DIR"); env && *env) dirs.emplace_back(env);
    dirs.push_back(exe / ".." / "lib" / "evio");
    dirs.push_back(exe / ".." / ".." / "lib" / "evio");
    const fs::path dest = fs::path(o_.dir) / "parallel" / "lib" / "evio";
    for (const fs::path& d : dirs) {
      std::error_code ec;
      if (!fs::is_directory(d, ec)) continue;
      bool any = false;
      for (const fs::directory_entry& e : fs::directory_iterator(d, ec)) {
        if (e.path().extension() != ".so") continue;
        fs::create_directories(dest);
        link_or_copy(e.path(), dest / e.path().filename());
        any = true;
      }
      if (any) return true;
    }
    return false;
  }

  static void link_or_copy(const fs::path& from, const fs::path& to) {
    std::error_code ec;
    fs::remove(to, ec);
    fs::create_hard_link(from, to, ec);
    if (ec) fs::copy_file(from, to, fs::copy_options::overwrite_existing);
  }

  // Relative to the login's home: ~/.evio-sweep/<this host>-<hash of DIR>.
  std::string remote_workdir() const {
    char hash[17];
    std::snprintf(hash, sizeof(hash), "%016zx", std::hash<std::string>()(o_.dir));
    return ".evio-sweep/" + sweep_hostname() + "-" + hash;
  }

  SweepEngineOptions o_;
};

std::vector<std::string> split_words(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

class SlurmEngine : public SweepEngine {
 public:
  explicit SlurmEngine(const SweepEngineOptions& o) : o_(o) {
    for (const char* p : {"sbatch", "squeue", "scancel", "scontrol"}) {
      if (!on_path(p)) throw std::invalid_argument(std::string("--engine slurm: ") + p + " is not on PATH (a Slurm client: Debian slurm-client or slurm-wlm)");
    }
    if (o_.runner.empty()) o_.runner = sweep_self_program();
    o_.dir = fs::absolute(o_.dir).lexically_normal().string();
    while (o_.dir.size() > 1 && o_.dir.back() == '/') o_.dir.pop_back();
  }
  std::string name() const override { return "slurm"; }

  void run(const std::vector<SweepJob>& jobs, const std::function<void(size_t, const SweepOutcome&)>& done) override {
    if (jobs.empty()) return;
    const fs::path sdir = fs::path(o_.dir) / "slurm";
    fs::create_directories(sdir);
    const std::string stem = next_run_stem(sdir);
    std::ostringstream lines;
    double max_timeout = 0;
    for (const SweepJob& job : jobs) {
      std::error_code ec;
      fs::remove(sweep_outcome_path(job), ec);
      lines << command_of(o_.runner, run_cell_arguments(with_absolute_paths(job))) << "\n";
      max_timeout = job.timeout_s > 0 && max_timeout >= 0 ? std::max(max_timeout, job.timeout_s) : -1;  // -1: a job without a limit
    }
    sweep_write_file(stem + ".jobs", lines.str());
    sweep_write_file(stem + ".sh", slurm_array_script(o_, jobs.size(), stem + ".jobs", stem, max_timeout));
    int st = 0;
    const std::string sub = capture("sbatch --parsable " + sweep_shell_quote(stem + ".sh"), &st);
    const std::string job_id = sub.substr(0, sub.find_first_of(";\n"));
    if (st != 0 || job_id.empty() || job_id.find_first_not_of("0123456789") != std::string::npos) {
      for (size_t i = 0; i < jobs.size(); ++i) done(i, sweep_outcome_without_file(jobs[i], 127, 0, "", "sbatch failed: " + sub));
      return;
    }
    sweep_write_file(stem + ".jobid", job_id + "\n");
    std::vector<bool> reported(jobs.size(), false);
    std::vector<int> gone_polls(jobs.size(), 0);  // polls since the task left the queue without an outcome
    size_t left = jobs.size();
    int failed_polls = 0;
    while (left > 0) {
      if (sweep_stop_requested()) {
        capture("scancel " + job_id, &st);
        return;
      }
      // Outcome files first: a task that wrote one is done.
      for (size_t i = 0; i < jobs.size(); ++i) {
        SweepOutcome o;
        if (!reported[i] && read_outcome(jobs[i], &o)) {
          reported[i] = true;
          --left;
          done(i, o);
        }
      }
      if (left == 0) break;
      const std::string q = capture("squeue -h -r -j " + job_id + " -o %K", &st);
      std::set<size_t> queued;
      if (st == 0) {
        failed_polls = 0;
        for (const std::string& w : split_words(q)) queued.insert(std::strtoul(w.c_str(), nullptr, 10));
      } else if (q.find("Invalid job id") == std::string::npos && ++failed_polls < 60) {
        std::this_thread::sleep_for(std::chrono::seconds(1));
        continue;  // the controller did not answer: ask again
      }
      for (size_t i = 0; i < jobs.size(); ++i) {
        if (reported[i] || queued.count(i) || ++gone_polls[i] < 3) continue;  // 3 polls of grace for the file to appear
        const auto [code, state] = task_exit(job_id, i);
        reported[i] = true;
        --left;
        done(i, sweep_outcome_without_file(jobs[i], code, 0, "", "Slurm task " + job_id + "_" + std::to_string(i) + " ended " + state +
                                                               " (its Slurm log: " + stem + "-" + std::to_string(i) + ".err)"));
      }
      std::this_thread::sleep_for(std::chrono::seconds(1));
    }
  }

 private:
  // The exit code and state Slurm reports for a task that has left the queue.
  std::pair<int, std::string> task_exit(const std::string& job_id, size_t task) {
    int st = 0;
    const std::string id = job_id + "_" + std::to_string(task);
    const std::string s = capture("scontrol -o show job " + id, &st);
    auto field = [](const std::string& text, const std::string& key) {
      const size_t p = text.find(" " + key + "=");
      if (p == std::string::npos) return std::string();
      const size_t b = p + key.size() + 2;
      return text.substr(b, text.find_first_of(" \n", b) - b);
    };
    if (st == 0 && !field(s, "ExitCode").empty()) return {slurm_exit_code(field(s, "ExitCode")), field(s, "JobState")};
    const std::string a = capture("sacct -n -X -P -j " + id + " -o ExitCode,State", &st);
    const size_t bar = a.find('|');
    if (st == 0 && bar != std::string::npos) return {slurm_exit_code(a.substr(0, bar)), a.substr(bar + 1, a.find('\n') - bar - 1)};
    return {127, "(unknown to scontrol and sacct)"};
  }

  SweepEngineOptions o_;
};

}  // namespace

std::string sweep_shell_quote(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=./,:@") == std::string::npos) return s;
  std::string o = "'";
  for (char c : s) o += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return o + "'";
}

std::string sweep_outcome_path(const SweepJob& job) {
  const std::string tail = "stdout.log";
  const std::string& p = job.stdout_path;
  if (p.size() >= tail.size() && p.compare(p.size() - tail.size(), tail.size(), tail) == 0) return p.substr(0, p.size() - tail.size()) + "outcome.json";
  return p + ".outcome.json";
}

std::string sweep_outcome_json(const SweepOutcome& o) {
  std::ostringstream j;
  j << "{\"exit_code\": " << o.exit_code << ", \"timed_out\": " << json_bool(o.timed_out) << ", \"wall_s\": " << json_number(o.wall_s)
    << ", \"cpu_s\": " << json_number(o.cpu_s) << ", \"peak_rss_mb\": " << json_number(o.peak_rss_mb) << ", \"host\": " << json_string(o.host)
    << ", \"started_utc\": " << json_string(o.started_utc) << "}\n";
  return j.str();
}

bool parse_sweep_outcome(const std::string& text, SweepOutcome* o) {
  if (text.empty()) return false;
  YAML::Node n;
  try {
    n = YAML::Load(text);
    if (!n.IsMap() || !n["exit_code"] || !n["wall_s"]) return false;
    auto num = [&](const char* k) { return n[k] && n[k].Scalar() != "null" ? n[k].as<double>() : NAN; };
    o->exit_code = n["exit_code"].as<int>();
    o->timed_out = n["timed_out"] && n["timed_out"].as<bool>();
    o->wall_s = num("wall_s");
    o->cpu_s = num("cpu_s");
    o->peak_rss_mb = num("peak_rss_mb");
    o->host = n["host"] ? n["host"].Scalar() : "";
    o->started_utc = n["started_utc"] ? n["started_utc"].Scalar() : "";
  } catch (const YAML::Exception&) {
    return false;
  }
  return true;
}

std::vector<std::string> run_cell_arguments(const SweepJob& job) {
  char t[40];
  std::snprintf(t, sizeof(t), "%.17g", job.timeout_s);
  std::vector<std::string> a = {"--run-cell", sweep_outcome_path(job), "--timeout", t, "--stdout", job.stdout_path, "--stderr", job.stderr_path, "--", job.program};
  a.insert(a.end(), job.args.begin(), job.args.end());
  return a;
}

SweepJob parse_run_cell_arguments(const std::vector<std::string>& args, std::string* outcome_path) {
  const std::string form = "--run-cell OUTCOME.json --timeout S --stdout FILE --stderr FILE -- PROGRAM [ARGS...]";
  SweepJob j;
  size_t i = 0;
  bool have_timeout = false;
  outcome_path->clear();
  for (; i < args.size() && args[i] != "--"; i += 2) {
    if (i + 1 >= args.size()) throw InputError("evio sweep --run-cell", 0, args[i] + " has no value", form);
    const std::string& v = args[i + 1];
    if (args[i] == "--run-cell") {
      *outcome_path = v;
    } else if (args[i] == "--timeout") {
      char* end = nullptr;
      j.timeout_s = std::strtod(v.c_str(), &end);
      if (v.empty() || *end || !(j.timeout_s >= 0)) throw InputError("evio sweep --run-cell", 0, "--timeout " + v + " is not a number of seconds >= 0", form);
      have_timeout = true;
    } else if (args[i] == "--stdout") {
      j.stdout_path = v;
    } else if (args[i] == "--stderr") {
      j.stderr_path = v;
    } else {
      throw InputError("evio sweep --run-cell", 0, "unknown option " + args[i], form);
    }
  }
  if (i + 1 >= args.size() || outcome_path->empty() || !have_timeout || j.stdout_path.empty() || j.stderr_path.empty()) {
    throw InputError("evio sweep --run-cell", 0, "incomplete arguments", form);
  }
  j.program = args[i + 1];
  j.args.assign(args.begin() + static_cast<std::ptrdiff_t>(i) + 2, args.end());
  return j;
}

int run_cell(const std::vector<std::string>& args) {
  std::string outcome_path;
  const SweepJob job = parse_run_cell_arguments(args, &outcome_path);
  std::error_code ec;
  for (const std::string& p : {outcome_path, job.stdout_path, job.stderr_path}) {
    const fs::path parent = fs::path(p).parent_path();
    if (!parent.empty()) fs::create_directories(parent, ec);
  }
  const SweepOutcome o = run_job(job);
  try {
    write_atomically(outcome_path, sweep_outcome_json(o));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "evio sweep --run-cell: %s\n", e.what());
    return 125;
  }
  return o.exit_code >= 0 ? o.exit_code : 128 - o.exit_code;
}

std::vector<ParallelJoblogEntry> parse_parallel_joblog(const std::string& text) {
  std::vector<ParallelJoblogEntry> out;
  size_t b = 0;
  while (true) {
    const size_t e = text.find('\n', b);
    if (e == std::string::npos) break;  // a line still being written
    const std::string line = text.substr(b, e - b);
    b = e + 1;
    std::vector<std::string> f;
    std::stringstream s(line);
    std::string x;
    while (std::getline(s, x, '\t')) f.push_back(x);
    if (f.size() < 8 || f[0] == "Seq" || f[0].find_first_not_of("0123456789") != std::string::npos) continue;
    ParallelJoblogEntry j;
    j.seq = std::strtoul(f[0].c_str(), nullptr, 10);
    j.host = f[1];
    j.runtime_s = std::strtod(f[3].c_str(), nullptr);
    j.exit_value = std::atoi(f[6].c_str());
    j.signal = std::atoi(f[7].c_str());
    out.push_back(j);
  }
  return out;
}

int slurm_exit_code(const std::string& field) {
  const size_t colon = field.find(':');
  const int code = std::atoi(field.substr(0, colon).c_str());
  const int sig = colon == std::string::npos ? 0 : std::atoi(field.substr(colon + 1).c_str());
  return sig != 0 ? -sig : code;
}

std::string slurm_array_script(const SweepEngineOptions& o, size_t count, const std::string& jobs_file, const std::string& log_stem,
                               double max_timeout_s) {
  std::ostringstream s;
  s << "#!/bin/bash\n# evio sweep: one array task per job; task N runs line N+1 of " << jobs_file << "\n";
  s << "#SBATCH --job-name=evio-sweep\n";
  s << "#SBATCH --array=0-" << count - 1;
  if (o.jobs > 0) s << "%" << o.jobs;
  s << "\n#SBATCH --output=" << log_stem << "-%a.out\n#SBATCH --error=" << log_stem << "-%a.err\n";
  s << "#SBATCH --chdir=" << o.dir << "\n#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=1\n";
  if (max_timeout_s > 0) s << "#SBATCH --time=" << static_cast<long>(std::ceil(max_timeout_s / 60.0)) + 1 << "\n";  // minutes: the cell timeout + 1
  if (!o.slurm_partition.empty()) s << "#SBATCH --partition=" << o.slurm_partition << "\n";
  for (const std::string& a : split_words(o.slurm_args)) s << "#SBATCH " << a << "\n";
  s << "line=$(sed -n \"$((SLURM_ARRAY_TASK_ID + 1))p\" " << sweep_shell_quote(jobs_file) << ")\n";
  s << "eval \"exec $line\"\n";
  return s.str();
}

std::unique_ptr<SweepEngine> make_parallel_engine(const SweepEngineOptions& options) { return std::make_unique<ParallelEngine>(options); }
std::unique_ptr<SweepEngine> make_slurm_engine(const SweepEngineOptions& options) { return std::make_unique<SlurmEngine>(options); }

}  // namespace evio::sweep
