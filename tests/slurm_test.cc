// `imr submit` on a real Slurm cluster (issue 7): the test starts a one-node cluster on localhost
// (Debian's slurm-wlm and munge, installed by tools/setup.sh) with its state, sockets and logs
// in a temporary folder, submits a 4-sequence job as a 2-task array plus the reduce job (its batch
// folder's path holds a blank, '#' and '%'), waits, checks every mesh, the task logs and the
// summary, and stops the daemons by their PIDs. Cgroups are not available on these machines
// (and fail silently), hence proctrack/linuxproc and task/none.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <random>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

const std::string kImr = IMR_EXE;

// A TCP port nobody listens on now (the kernel's choice).
int FreePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(a);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a));
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

std::string Which(const std::string& program) {
  const auto r = RunShell("PATH=\"$PATH:/usr/sbin:/sbin\" command -v " + program);
  return r.status == 0 ? r.out.substr(0, r.out.find('\n')) : "";
}

class SlurmCluster {
 public:
  explicit SlurmCluster(fs::path dir) : dir_(std::move(dir)) {}
  ~SlurmCluster() { Stop(); }

  // Starts munged, slurmctld and slurmd; false with `why` when they do not come up.
  bool Start(std::string* why) {
    char host[256] = {};
    ::gethostname(host, sizeof(host) - 1);
    const std::string node = std::string(host).substr(0, std::string(host).find('.'));
    for (const char* d : {"munge", "state", "spool", "log"}) fs::create_directories(dir_ / d);
    fs::permissions(dir_ / "munge", fs::perms::owner_all | fs::perms::group_exec | fs::perms::others_exec);
    {
      std::random_device rd;
      std::ofstream key(dir_ / "munge" / "munge.key", std::ios::binary);
      for (int i = 0; i < 1024; ++i) key.put(static_cast<char>(rd()));
    }
    ::chmod((dir_ / "munge" / "munge.key").c_str(), 0400);
    const std::string d = dir_.string();
    auto r = RunShell(Which("munged") + " -f --key-file=" + Quote(d + "/munge/munge.key") +
                      " --socket=" + Quote(d + "/munge/munge.sock") + " --pid-file=" +
                      Quote(d + "/munge/munged.pid") + " --log-file=" + Quote(d + "/log/munged.log") +
                      " --seed-file=" + Quote(d + "/munge/munged.seed"));
    if (r.status != 0) return Fail(why, "munged did not start: " + r.err);
    pid_files_.push_back(dir_ / "munge" / "munged.pid");

    const unsigned cpus = std::max(1u, std::thread::hardware_concurrency());
    std::ostringstream conf;
    conf << "ClusterName=imrtest\n"
         << "SlurmctldHost=" << node << "(127.0.0.1)\n"
         << "SlurmctldPort=" << FreePort() << "\nSlurmdPort=" << FreePort() << "\n"
         << "SlurmUser=root\nSlurmdUser=root\n"
         << "AuthType=auth/munge\nCredType=cred/munge\n"
         << "AuthInfo=socket=" << d << "/munge/munge.sock\n"
         << "StateSaveLocation=" << d << "/state\nSlurmdSpoolDir=" << d << "/spool\n"
         << "SlurmctldPidFile=" << d << "/slurmctld.pid\nSlurmdPidFile=" << d << "/slurmd.pid\n"
         << "SlurmctldLogFile=" << d << "/log/slurmctld.log\nSlurmdLogFile=" << d << "/log/slurmd.log\n"
         << "PlugStackConfig=" << d << "/plugstack.conf\n"
         << "ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\n"
         << "SelectType=select/cons_tres\nSelectTypeParameters=CR_Core_Memory\n"
         << "JobAcctGatherType=jobacct_gather/none\nAccountingStorageType=accounting_storage/none\n"
         << "MpiDefault=none\nSwitchType=switch/none\nReturnToService=2\n"
         << "SchedulerParameters=sched_min_interval=0\n"
         << "NodeName=" << node << " NodeAddr=127.0.0.1 CPUs=" << cpus
         << " RealMemory=2048 State=UNKNOWN\n"
         << "PartitionName=imrtest Nodes=" << node << " Default=YES MaxTime=INFINITE State=UP\n";
    WriteText(dir_ / "slurm.conf", conf.str());
    WriteText(dir_ / "plugstack.conf", "");
    env_ = "SLURM_CONF=" + Quote(d + "/slurm.conf") + " ";

    r = RunShell(env_ + Which("slurmctld"));
    if (r.status != 0) return Fail(why, "slurmctld did not start: " + r.err + Logs());
    pid_files_.push_back(dir_ / "slurmctld.pid");
    r = RunShell(env_ + Which("slurmd"));
    if (r.status != 0) return Fail(why, "slurmd did not start: " + r.err + Logs());
    pid_files_.push_back(dir_ / "slurmd.pid");

    const auto deadline = Clock::now() + std::chrono::seconds(60);
    while (Clock::now() < deadline) {
      r = RunShell(env_ + "sinfo -h -o %T");
      // "idle*" would be a node that has not registered yet.
      if (r.status == 0 && r.out == "idle\n") return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
    }
    return Fail(why, "the node did not become idle (sinfo: " + r.out + r.err + ")" + Logs());
  }

  // SIGTERM to each daemon by its PID, SIGKILL after 10 s.
  void Stop() {
    for (auto it = pid_files_.rbegin(); it != pid_files_.rend(); ++it) {
      const pid_t pid = static_cast<pid_t>(std::atoi(ReadText(*it).c_str()));
      if (pid <= 1) continue;
      ::kill(pid, SIGTERM);
      const auto deadline = Clock::now() + std::chrono::seconds(10);
      while (::kill(pid, 0) == 0 && Clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      if (::kill(pid, 0) == 0) ::kill(pid, SIGKILL);
    }
    pid_files_.clear();
  }

  // Environment for Slurm's commands (and, through sbatch, for the jobs).
  const std::string& env() const { return env_; }

  std::string Logs() const {
    std::string s;
    for (const char* f : {"slurmctld.log", "slurmd.log", "munged.log"}) {
      const std::string text = ReadText(dir_ / "log" / f);
      s += "\n--- " + std::string(f) + " (end) ---\n" + text.substr(text.size() > 3000 ? text.size() - 3000 : 0);
    }
    return s;
  }

 private:
  bool Fail(std::string* why, const std::string& what) {
    *why = what;
    return false;
  }
  fs::path dir_;
  std::string env_;
  std::vector<fs::path> pid_files_;
};

std::set<std::string> OkLines(const std::string& log) {
  std::set<std::string> names;
  std::istringstream in(log);
  for (std::string line; std::getline(in, line);)
    if (line.rfind("ok ", 0) == 0) {
      std::istringstream words(line.substr(3));
      std::string name;
      words >> name;
      names.insert(name);
    }
  return names;
}

TEST(Slurm, ArrayJobAndReduceJobMakeEveryMeshAndTheSummary) {
  for (const char* p : {"munged", "slurmctld", "slurmd", "sbatch", "squeue", "sinfo"})
    if (Which(p).empty())
      GTEST_SKIP() << "Slurm is not installed (no " << p
                   << "): tools/setup.sh installs Debian's slurm-wlm and munge";
  if (::geteuid() != 0) GTEST_SKIP() << "the one-node cluster needs root (slurmd starts the jobs)";
  const auto start = Clock::now();
  ScratchDir dir("slurm");
  SlurmCluster cluster(dir / "cluster");
  std::string why;
  ASSERT_TRUE(cluster.Start(&why)) << why;
  const double startup = std::chrono::duration<double>(Clock::now() - start).count();

  // Four sequences: SLAM JSON streams of synthetic scenes, one folder each.
  auto make = [&](const std::vector<std::string>& scenes, int seed, const std::string& export_to) {
    const json j = {{"sequences", scenes},
                    {"input", {{"format", "synthetic"}, {"options", {{"frames", 25}, {"seed", seed}}}}},
                    {"pipeline", {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
                                  {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
                    {"output", {{"directory", "scratch/{sequence}"}, {"formats", {"ply"}}}}};
    WriteText(dir / "make.json", j.dump());
    const auto r = RunShell(Quote(kImr) + " run -q " + Quote((dir / "make.json").string()) +
                            " --export-stream " + Quote(export_to));
    ASSERT_EQ(r.status, 0) << r.out << r.err;
  };
  make({"street", "room", "plane"}, 3, (dir / "data/{sequence}/stream.json").string());
  make({"street"}, 4, (dir / "data/street2/stream.json").string());
  const json job = {{"sequences", {"data/*/stream.json"}},
                    {"input", {{"format", "slam_json"}}},
                    {"pipeline", {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
                                  {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
                    // A batch folder with a blank, a '#' and a '%' in its path: sbatch reads
                    // #SBATCH lines with its own quoting ('#' starts a comment, '%' a file name
                    // pattern), and an unquoted --output= lost the task logs.
                    {"output", {{"directory", "my runs #2 (100%)/{sequence}"}, {"formats", {"ply", "glb"}}}}};
  WriteText(dir / "job.json", job.dump(2));

  const auto submitted = Clock::now();
  auto r = RunShell("cd " + Quote(dir.path().string()) + " && " + cluster.env() + Quote(kImr) +
                    " submit job.json --tasks 2 --time 10:00 --mem 500M");
  ASSERT_EQ(r.status, 0) << r.out << r.err << cluster.Logs();
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.out, m, std::regex("submitted array job (\\d+) and reduce job (\\d+)")))
      << r.out;
  const std::string array_id = m[1], reduce_id = m[2];
  const fs::path runs = dir / "my runs #2 (100%)";
  EXPECT_NE(r.out.find("summary (when job " + reduce_id + " has run): " + (runs / "summary.md").string()),
            std::string::npos) << r.out;

  // Both jobs leave the queue when done.
  const auto deadline = Clock::now() + std::chrono::seconds(240);
  bool done = false;
  while (!done && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    const auto q = RunShell(cluster.env() + "squeue -h -j " + array_id + "," + reduce_id);
    done = q.status == 0 && q.out.find_first_not_of(" \n") == std::string::npos &&
           fs::exists(runs / "summary.json");
  }
  const double waited = std::chrono::duration<double>(Clock::now() - submitted).count();
  const fs::path logs = runs / "imr-batch" / "slurm" / "logs";
  const std::string log0 = ReadText(logs / ("array-" + array_id + "_0.out"));
  const std::string log1 = ReadText(logs / ("array-" + array_id + "_1.out"));
  const std::string reduce_log = ReadText(logs / ("report-" + reduce_id + ".out"));
  ASSERT_TRUE(done) << "the jobs did not finish in time\n" << log0 << log1 << reduce_log
                    << RunShell(cluster.env() + "squeue; scontrol show job " + array_id).out
                    << cluster.Logs();

  // Each task ran its shard; together every sequence exactly once.
  EXPECT_NE(log0.find("shard 1/2 (Slurm array task 0)"), std::string::npos) << log0;
  EXPECT_NE(log1.find("shard 2/2 (Slurm array task 1)"), std::string::npos) << log1;
  const auto a = OkLines(log0), b = OkLines(log1);
  std::multiset<std::string> all(a.begin(), a.end());
  all.insert(b.begin(), b.end());
  EXPECT_EQ(all, (std::multiset<std::string>{"plane", "room", "street", "street2"})) << log0 << log1;

  for (const char* s : {"plane", "room", "street", "street2"}) {
    for (const char* f : {"mesh.ply", "mesh.glb", "report.json", "manifest.json"})
      EXPECT_TRUE(fs::is_regular_file(runs / s / f)) << s << "/" << f;
    const json report = json::parse(ReadText(runs / s / "report.json"));
    EXPECT_TRUE(report["mesh"]["manifold"].get<bool>()) << s;
    EXPECT_GT(report["mesh"]["faces"].get<int>(), 100) << s;
  }
  const json summary = json::parse(ReadText(runs / "summary.json"));
  EXPECT_EQ(summary["written_by"], "imr report");
  EXPECT_EQ(summary["counts"]["ok"], 4) << summary.dump(2);
  EXPECT_EQ(summary["counts"]["failed"], 0);
  const std::string md = ReadText(runs / "summary.md");
  for (const char* s : {"plane", "room", "street", "street2"})
    EXPECT_NE(md.find("| " + std::string(s) + " | ok |"), std::string::npos) << md;
  EXPECT_NE(reduce_log.find("4 sequences: 4 ok, 0 failed\n"), std::string::npos) << reduce_log;
  const auto state = RunShell(cluster.env() + "scontrol show job " + reduce_id);
  EXPECT_NE(state.out.find("JobState=COMPLETED"), std::string::npos) << state.out;
  EXPECT_NE(state.out.find("Dependency=(null)"), std::string::npos) << state.out;
  std::printf("cluster up in %.2f s; array + reduce jobs done %.1f s after submission\n", startup, waited);
}

}  // namespace
}  // namespace imr::testing
