// The sbatch scripts of `imr submit` against hostile values (issue 36): a property test over
// random partitions, accounts, time limits, sizes, sbatch options, job file names, sequence
// names and --set values. Values Slurm cannot take are refused by SubmitOptions::Check; for the
// others the scripts are written (a dry run) and then read back: `bash -n` parses them, their
// lines are exactly the intended ones (the comments, one #SBATCH line per option, then the
// commands), each #SBATCH value unquotes to what was given, running them hands the imr
// executable exactly the intended words, and the frozen sequence list reads back the names.
#include "host/batch/slurm.h"

#include "host/batch/batch.h"
#include "host/batch/child.h"
#include "host/batch/summary.h"
#include "host/util/atomic_file.h"
#include "host/util/shell.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>
#include <random>
#include <regex>
#include <sstream>

namespace imr::batch {
namespace {
namespace fs = std::filesystem;

// Characters a hostile value is made of: shell syntax, quotes, control characters, a byte that
// is not UTF-8, Slurm's '%' patterns and '#' comments.
const std::string kAlphabet = std::string("aZ09:-_.,=+ \t\n\r'\"\\#$`;&|()<>*?%!~{}@") + "\x7f\x01\xff";

class Random {
 public:
  explicit Random(uint32_t seed) : rng_(seed) {}
  int Int(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }
  bool Chance(double p) { return std::bernoulli_distribution(p)(rng_); }
  std::string Word(const std::string& alphabet, int max_length) {
    std::string w;
    for (int n = Int(1, max_length); n > 0; --n) w += alphabet[Int(0, static_cast<int>(alphabet.size()) - 1)];
    return w;
  }
  std::string Hostile(int max_length = 12) { return Word(kAlphabet, max_length); }
  // A plain value most of the time (the script must carry it), else a hostile one.
  std::string Value(const std::string& plain) { return Chance(0.5) ? plain : Hostile(); }
  std::string Time() {
    switch (Int(0, 5)) {
      case 0: return std::to_string(Int(1, 600));
      case 1: return std::to_string(Int(0, 48)) + ":" + std::to_string(Int(0, 59)) + ":00";
      case 2: return std::to_string(Int(0, 9)) + "-" + std::to_string(Int(0, 23));
      case 3: return "UNLIMITED";
      case 4: return Word("0123456789:-", 10);  // often malformed
      default: return Hostile();
    }
  }
  std::string Memory() {
    switch (Int(0, 3)) {
      case 0: return std::to_string(Int(1, 64)) + "G";
      case 1: return std::to_string(Int(100, 9000));
      case 2: return Word("0123456789-KMGTkx.", 6);
      default: return Hostile();
    }
  }

 private:
  std::mt19937 rng_;
};

bool HasControl(const std::string& s) {
  for (const char c : s)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) return true;
  return false;
}

// The reference grammar (sbatch(1)): what Check must accept, written independently of it.
bool ReferenceTime(const std::string& t) {
  static const std::regex time(R"((\d{1,9}-)?\d{1,9}(:\d{1,9}){0,2}|UNLIMITED|INFINITE)",
                               std::regex::icase);
  return std::regex_match(t, time);
}
bool ReferenceMemory(const std::string& m) {
  static const std::regex mem(R"(\d{1,15}[KMGTkmgt]?)");
  return std::regex_match(m, mem);
}

// An #SBATCH value as sbatch reads it back (the inverse of slurm.cc's SbatchValue): double
// quotes group, a backslash takes the next character as it is, "%%" in a file name is '%'.
std::string Unquote(const std::string& v, bool pattern) {
  std::string out;
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (v[i] == '"') continue;
    if (v[i] == '\\' && i + 1 < v.size()) ++i;
    out += v[i];
    if (pattern && v[i] == '%' && i + 1 < v.size() && v[i + 1] == '%') ++i;
  }
  return out;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::string Read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The words a program was run with, as the fake imr wrote them (NUL-terminated).
std::vector<std::string> Words(const std::string& out) {
  std::vector<std::string> words;
  for (std::size_t pos = 0; pos < out.size();) {
    const std::size_t end = out.find('\0', pos);
    words.push_back(out.substr(pos, end - pos));
    pos = end == std::string::npos ? out.size() : end + 1;
  }
  return words;
}

class SlurmScripts : public ::testing::Test {
 protected:
  SlurmScripts() {
    dir_ = fs::temp_directory_path() / ("imr-slurm-script-test-" + std::to_string(std::random_device{}()));
    fs::create_directories(dir_);
  }
  ~SlurmScripts() override { fs::remove_all(dir_); }

  // A fake imr, named with blanks, quotes and a newline, that writes the words it was given
  // into Words() (NUL-terminated: every byte as it came).
  fs::path FakeImr() {
    const fs::path exe = dir_ / "bin dir" / "i'm \"imr\"\nx";
    fs::create_directories(exe.parent_path());
    WriteFileAtomically(exe, "#!/bin/sh\nfor a; do printf '%s\\0' \"$a\"; done >" +
                                 ShellQuote((dir_ / "words").string()) + "\n");
    ::chmod(exe.c_str(), 0755);
    return exe;
  }
  std::vector<std::string> WordsGiven() const { return Words(Read(dir_ / "words")); }

  fs::path dir_;
};

TEST_F(SlurmScripts, CheckRefusesWhatSlurmCannotTake) {
  SubmitOptions o;
  o.executable = "imr";
  EXPECT_EQ(o.Check(), "");
  auto refused = [&](auto set, const std::string& what) {
    SubmitOptions bad = o;
    set(bad);
    EXPECT_NE(bad.Check().find(what), std::string::npos) << bad.Check();
  };
  refused([](SubmitOptions& b) { b.time = "1:00:00\ntouch X #"; }, "--time: expected a Slurm time limit");
  refused([](SubmitOptions& b) { b.time = "1:00:00\ntouch X #"; }, "got '1:00:00\\ntouch X #'");
  refused([](SubmitOptions& b) { b.time = "1:2:3:4"; }, "--time");
  refused([](SubmitOptions& b) { b.mem = "-5G"; }, "--mem: expected a memory size");
  refused([](SubmitOptions& b) { b.mem = "8GB"; }, "--mem");
  refused([](SubmitOptions& b) { b.partition = "gpu\nrm -rf ~"; }, "--partition: 'gpu\\nrm -rf ~' holds a control character");
  refused([](SubmitOptions& b) { b.account = "a\rb"; }, "--account");
  refused([](SubmitOptions& b) { b.qos = "q\x7f"; }, "--qos");
  refused([](SubmitOptions& b) { b.sbatch_args = {"--constraint=x\ntouch Y"}; }, "--sbatch-arg");
  refused([](SubmitOptions& b) { b.sbatch_args = {"touch Y"}; }, "expected an sbatch option");
  for (const char* t : {"30", "30:00", "2:00:00", "1-0", "1-12:30", "2-00:00:00", "unlimited"}) {
    SubmitOptions good = o;
    good.time = t;
    EXPECT_EQ(good.Check(), "") << t;
  }
  for (const char* m : {"0", "512", "8G", "16g", "100M", "1T", "2048k"}) {
    SubmitOptions good = o;
    good.mem = m;
    EXPECT_EQ(good.Check(), "") << m;
  }
  EXPECT_NE(CheckScriptPaths(dir_ / "runs\ntouch Z #"), "");
  EXPECT_EQ(CheckScriptPaths(dir_ / "runs with # and %"), "");
}

TEST_F(SlurmScripts, NoLineButTheIntendedOnesForRandomValues) {
  const fs::path imr = FakeImr();
  Random random(20261128);
  int written = 0, refused = 0;
  for (int trial = 0; trial < 150; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    const fs::path root = dir_ / ("t" + std::to_string(trial));
    fs::create_directories(root);
    // The job: a hostile file name and batch folder (no '/', no placeholder braces), names and
    // a --set value of any bytes.
    auto path_part = [&] {
      std::string w = random.Hostile(10);
      for (char& c : w)
        if (c == '/' || c == '{' || c == '}' || c == '\n' || c == '\r' ||
            static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
          c = '_';
      return w == "." || w == ".." ? std::string("x") : w;
    };
    pipeline::ValidatedJob v;
    std::string job_name = random.Hostile(10);
    for (char& c : job_name)
      if (c == '/') c = '_';
    v.job.file = root / (job_name + ".json");
    v.job.base_dir = root;
    v.job.output.directory = (root / ("runs " + path_part()) / "{sequence}").string();
    v.job.input.format = "synthetic";
    std::string a = random.Hostile(8), b = random.Hostile(8);
    if (a == b) b += "2";
    for (std::string* n : {&a, &b})
      for (char& c : *n)
        if (c == '/') c = '_';
    v.sequences = {{a, a}, {b, b}};
    v.job.overrides = {"engine.window=" + random.Hostile(8)};
    std::ofstream(v.job.file) << "{}";

    SubmitOptions o;
    o.tasks = random.Int(1, 3);
    o.executable = imr.string();
    o.dry_run = true;
    if (random.Chance(0.5)) o.partition = random.Value("gpu,cpu");
    if (random.Chance(0.4)) o.account = random.Value("proj-12");
    if (random.Chance(0.3)) o.qos = random.Value("normal");
    if (random.Chance(0.7)) o.time = random.Time();
    if (random.Chance(0.6)) o.mem = random.Memory();
    for (int n = random.Int(0, 2); n > 0; --n)
      o.sbatch_args.push_back(random.Chance(0.5) ? "--constraint=" + random.Word("abc|&", 5) : random.Hostile());

    bool acceptable = (o.time.empty() || ReferenceTime(o.time)) && (o.mem.empty() || ReferenceMemory(o.mem));
    for (const std::string* s : {&o.partition, &o.account, &o.qos}) acceptable &= !HasControl(*s);
    for (const std::string& s : o.sbatch_args) acceptable &= !HasControl(s) && s[0] == '-';
    const std::string check = o.Check();
    EXPECT_EQ(check.empty(), acceptable) << "Check(): '" << check << "'";
    if (!check.empty()) {
      ++refused;
      continue;
    }
    ++written;
    const SubmitResult r = Submit(v, plugin::PluginRegistry(), pipeline::RunOptions(), o);

    // Both scripts parse.
    for (const fs::path& script : {r.array_script, r.reduce_script}) {
      std::string out, err;
      EXPECT_EQ(RunAndCapture({"bash", "-n", script.string()}, &out, &err), 0) << err << Read(script);
    }
    // The array script's lines: the shebang and comments, the #SBATCH block, three commands.
    const std::vector<std::string> lines = Lines(Read(r.array_script));
    std::vector<std::string> sbatch, commands;
    for (std::size_t i = 1; i < lines.size(); ++i) {
      const std::string& l = lines[i];
      if (l.rfind("#SBATCH ", 0) == 0) {
        EXPECT_TRUE(commands.empty()) << "an #SBATCH line after a command: " << l;
        sbatch.push_back(l.substr(8));
      } else if (l.rfind("# ", 0) != 0) {
        commands.push_back(l);
      }
    }
    ASSERT_EQ(lines[0], "#!/bin/bash");
    const std::size_t options = 4 + !o.partition.empty() + !o.account.empty() + !o.qos.empty() +
                                !o.time.empty() + !o.mem.empty() + o.sbatch_args.size();
    EXPECT_EQ(lines.size(), 1 + 6 + options + 3) << Read(r.array_script);
    EXPECT_EQ(sbatch.size(), options);
    ASSERT_EQ(commands.size(), 3u) << Read(r.array_script);
    EXPECT_EQ(commands[0], "set -eu");
    EXPECT_EQ(commands[1].rfind("cd ", 0), 0u);
    EXPECT_EQ(commands[2].rfind("exec ", 0), 0u);
    // Each #SBATCH value reads back as given.
    std::map<std::string, std::string> given;
    for (const std::string& s : sbatch) {
      const std::size_t eq = s.find('=');
      if (s.rfind("--", 0) == 0 && eq != std::string::npos)
        given[s.substr(0, eq)] = Unquote(s.substr(eq + 1), s.rfind("--output=", 0) == 0);
    }
    if (!o.partition.empty()) {
      EXPECT_EQ(given["--partition"], o.partition);
    }
    if (!o.account.empty()) {
      EXPECT_EQ(given["--account"], o.account);
    }
    if (!o.qos.empty()) {
      EXPECT_EQ(given["--qos"], o.qos);
    }
    if (!o.time.empty()) {
      EXPECT_EQ(given["--time"], o.time);
    }
    if (!o.mem.empty()) {
      EXPECT_EQ(given["--mem"], o.mem);
    }
    EXPECT_EQ(given["--output"], (r.log_directory / "array-%A_%a.out").string());
    for (const std::string& extra : o.sbatch_args)
      EXPECT_NE(std::find(sbatch.begin(), sbatch.end(), extra), sbatch.end()) << extra;
    EXPECT_EQ(given["--job-name"].find('\n'), std::string::npos);
    // Running them hands imr exactly the intended words.
    std::string out, err;
    ASSERT_EQ(RunAndCapture({"bash", r.array_script.string()}, &out, &err), 0) << err;
    EXPECT_EQ(out, "");
    const std::vector<std::string> expected = {
        "run", fs::absolute(v.job.file).lexically_normal().string(), "--sequences-from",
        (r.batch_directory / kBatchSubdir / "sequences.txt").string(), "--jobs", "1", "--set",
        v.job.overrides[0]};
    EXPECT_EQ(WordsGiven(), expected);
    ASSERT_EQ(RunAndCapture({"bash", r.reduce_script.string()}, &out, &err), 0) << err;
    EXPECT_EQ(WordsGiven(), (std::vector<std::string>{"report", r.batch_directory.string()}));
    const std::vector<std::string> reduce = Lines(Read(r.reduce_script));
    int reduce_commands = 0;
    for (const std::string& l : reduce) reduce_commands += l.empty() || l[0] != '#' ? 1 : 0;
    EXPECT_EQ(reduce_commands, 2) << Read(r.reduce_script);
    // The frozen list reads back the names.
    EXPECT_EQ(ReadSequenceList(r.batch_directory / kBatchSubdir / "sequences.txt"),
              (std::vector<std::string>{a, b}));
  }
  std::cout << "[ property ] " << written << " pairs of scripts written and read back, " << refused
            << " option sets refused\n";
  EXPECT_GT(written, 30);
  EXPECT_GT(refused, 30);
}

}  // namespace
}  // namespace imr::batch
