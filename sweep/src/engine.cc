#include "evio/sweep/engine.h"

#include "evio/sweep/cluster.h"
#include "evio/sweep/results.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstring>
#include <ctime>
#include <stdexcept>
#include <thread>

namespace evio::sweep {

namespace {

volatile std::sig_atomic_t g_stop = 0;

using Clock = std::chrono::steady_clock;

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// A started child: its pid (= its process group), start time and deadline.
struct Running {
  pid_t pid = -1;
  size_t index = 0;
  Clock::time_point start;
  SweepOutcome outcome;
};

// Starts the job in its own process group (a timeout kills the group: the child and what it
// started) with stdin from /dev/null and stdout/stderr to its logs; the child gets SIGKILL when the
// sweep dies (PR_SET_PDEATHSIG), so a sweep killed outright leaves no cell running. A program that
// cannot be started exits 127 with the reason in its stderr log.
Running spawn(const SweepJob& job, size_t index) {
  Running r;
  r.index = index;
  r.outcome.host = sweep_hostname();
  r.outcome.started_utc = utc_now();
  // Everything the child needs is prepared before fork (only async-signal-safe calls after it).
  std::vector<char*> argv;
  argv.push_back(const_cast<char*>(job.program.c_str()));
  for (const std::string& a : job.args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const std::string cannot_run = "evio sweep: cannot run " + job.program + ": ";
  const pid_t parent = getpid();
  r.start = Clock::now();
  r.pid = fork();
  if (r.pid == 0) {
    setpgid(0, 0);
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);  // the sweep died already
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
    for (int sig : {SIGINT, SIGTERM, SIGPIPE}) signal(sig, SIG_DFL);
    const int in = open("/dev/null", O_RDONLY);
    const int out = open(job.stdout_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = open(job.stderr_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (in < 0 || out < 0 || err < 0) _exit(127);
    dup2(in, 0);
    dup2(out, 1);
    dup2(err, 2);
    execv(job.program.c_str(), argv.data());
    const char* why = std::strerror(errno);
    (void)!write(2, cannot_run.data(), cannot_run.size());
    (void)!write(2, why, std::strlen(why));
    (void)!write(2, "\n", 1);
    _exit(127);
  }
  if (r.pid > 0) {
    setpgid(r.pid, r.pid);  // also from here, so the group exists before a kill
  } else {
    r.outcome.exit_code = 127;
    const int fd = open(job.stderr_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd >= 0) {
      const std::string m = cannot_run + "fork failed: " + std::strerror(errno) + "\n";
      (void)!write(fd, m.data(), m.size());
      close(fd);
    }
  }
  return r;
}

// Collects the child if it has ended (true), filling exit code, CPU time and peak RSS.
bool reap(Running* r, bool block) {
  int status = 0;
  rusage ru{};
  pid_t got;
  do {
    got = wait4(r->pid, &status, block ? 0 : WNOHANG, &ru);
  } while (got < 0 && errno == EINTR);
  if (got == 0) return false;
  SweepOutcome& o = r->outcome;
  o.wall_s = std::chrono::duration<double>(Clock::now() - r->start).count();
  if (got < 0) {  // cannot happen for our own child; record it as an internal failure
    o.exit_code = 127;
    return true;
  }
  o.exit_code = WIFSIGNALED(status) ? -WTERMSIG(status) : WEXITSTATUS(status);
  o.cpu_s = ru.ru_utime.tv_sec + ru.ru_utime.tv_usec * 1e-6 + ru.ru_stime.tv_sec + ru.ru_stime.tv_usec * 1e-6;
  o.peak_rss_mb = static_cast<double>(ru.ru_maxrss) / 1024.0;  // Linux: KiB
  return true;
}

void kill_group(pid_t pid) {
  if (kill(-pid, SIGKILL) != 0) kill(pid, SIGKILL);
}

// The job as `runner --run-cell ...` (cluster.h): the runner applies the job's timeout itself;
// this engine kills it only 30 s after that (a runner that hangs). Its own messages go to
// runner.log beside the job's logs; a stale outcome file is removed first.
SweepJob through_runner(const SweepJob& job, const std::string& runner) {
  SweepJob w;
  w.program = runner;
  w.args = run_cell_arguments(job);
  const std::string outcome = sweep_outcome_path(job);
  const size_t slash = outcome.rfind('/');
  w.stdout_path = w.stderr_path = (slash == std::string::npos ? std::string() : outcome.substr(0, slash + 1)) + "runner.log";
  w.timeout_s = job.timeout_s > 0 ? job.timeout_s + 30 : 0;
  std::remove(outcome.c_str());
  return w;
}

// The job's outcome from its runner's file; without one, what the runner's own end says.
SweepOutcome runner_outcome(const SweepJob& job, const SweepOutcome& runner) {
  SweepOutcome o;
  if (parse_sweep_outcome(sweep_read_file(sweep_outcome_path(job)), &o)) {
    o.host = runner.host;
    o.started_utc = runner.started_utc;
    return o;
  }
  o = sweep_outcome_without_file(job, runner.exit_code, runner.wall_s, runner.host,
                                 "its runner ended with exit code " + std::to_string(runner.exit_code) +
                                     (runner.timed_out ? " (killed 30 s after the cell's timeout)" : "") + "; see runner.log");
  o.timed_out = runner.timed_out;
  o.started_utc = runner.started_utc;
  return o;
}

// At most `jobs` children at once; a child past its timeout is killed with its process group. With
// a runner, each job runs as `runner --run-cell ...` (engine.h, "Peak RSS").
class LocalEngine : public SweepEngine {
 public:
  explicit LocalEngine(int jobs, std::string runner = {})
      : jobs_(jobs > 0 ? jobs : std::max(1u, std::thread::hardware_concurrency())), runner_(std::move(runner)) {}
  std::string name() const override { return "local"; }

  void run(const std::vector<SweepJob>& jobs, const std::function<void(size_t, const SweepOutcome&)>& done) override {
    std::vector<SweepJob> started = jobs;  // what is spawned: the jobs, or their runners
    if (!runner_.empty()) {
      for (SweepJob& j : started) j = through_runner(j, runner_);
    }
    std::vector<Running> running;
    size_t next = 0;
    while (next < jobs.size() || !running.empty()) {
      if (sweep_stop_requested()) {
        for (Running& r : running) kill_group(r.pid);
        for (Running& r : running) reap(&r, true);
        return;
      }
      while (static_cast<int>(running.size()) < jobs_ && next < jobs.size()) {
        Running r = spawn(started[next], next);
        ++next;
        if (r.pid < 0) {
          done(r.index, r.outcome);
        } else {
          running.push_back(std::move(r));
        }
      }
      bool any = false;
      for (size_t k = 0; k < running.size();) {
        Running& r = running[k];
        const double timeout = started[r.index].timeout_s;
        if (!r.outcome.timed_out && timeout > 0 &&
            std::chrono::duration<double>(Clock::now() - r.start).count() > timeout) {
          r.outcome.timed_out = true;
          kill_group(r.pid);  // with a runner: its job dies with it (PR_SET_PDEATHSIG)
        }
        if (reap(&r, false)) {
          const Running finished = std::move(r);
          running.erase(running.begin() + static_cast<std::ptrdiff_t>(k));
          done(finished.index, runner_.empty() ? finished.outcome : runner_outcome(jobs[finished.index], finished.outcome));
          any = true;
        } else {
          ++k;
        }
      }
      if (!any) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }

 private:
  int jobs_;
  std::string runner_;
};

}  // namespace

std::unique_ptr<SweepEngine> make_sweep_engine(const std::string& name, const SweepEngineOptions& options) {
  if (name == "local") {
    return std::make_unique<LocalEngine>(options.jobs, options.local_runner ? (options.runner.empty() ? sweep_self_program() : options.runner) : "");
  }
  if (name == "parallel") return make_parallel_engine(options);
  if (name == "slurm") return make_slurm_engine(options);
  throw std::invalid_argument("--engine " + name + ": unknown (engines: local, parallel, slurm)");
}

SweepOutcome run_job(const SweepJob& job) {
  SweepOutcome out;
  LocalEngine(1).run({job}, [&out](size_t, const SweepOutcome& o) { out = o; });
  return out;
}

std::string sweep_hostname() {
  char buf[256] = {0};
  if (gethostname(buf, sizeof(buf) - 1) != 0) return "unknown";
  return buf;
}

std::string sweep_self_program() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  return n > 0 ? std::string(buf, static_cast<size_t>(n)) : std::string("evio-sweep");
}

void request_sweep_stop() { g_stop = 1; }
bool sweep_stop_requested() { return g_stop != 0; }
void clear_sweep_stop() { g_stop = 0; }

}  // namespace evio::sweep
