// imr-bench: a table of subcommands, each a benchmark in its own file. `imr-bench --help` lists
// them; `imr-bench SUB --help` prints that subcommand's line and exits 0 (the subcommands parse
// their own options and refuse the ones they do not know).
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "tools/bench/common/subprocess.h"

namespace imr::bench {
int RunEngineBench(int argc, char** argv);
int RunPipelineBench(int argc, char** argv);
int RunPaperBench(int argc, char** argv);
int RunScalingBench(int argc, char** argv);
int RunStreamBench(int argc, char** argv);
int RunDriveBench(int argc, char** argv);
#ifdef IMR_BENCH_EVALUATE
int RunEvaluateBench(int argc, char** argv);
int RunPeersBench(int argc, char** argv);
int RunQualityBench(int argc, char** argv);
int RunPlanesBench(int argc, char** argv);
int RunSpeedBench(int argc, char** argv);
#endif
#ifdef IMR_BENCH_TEXTURE
int RunTextureBench(int argc, char** argv);
#endif
}  // namespace imr::bench

namespace {

struct Subcommand {
  const char* name;
  const char* options;      // the synopsis after the name
  const char* description;  // what it measures ('\n' between lines)
  int (*run)(int argc, char** argv);
};

const std::vector<Subcommand>& Subcommands() {
  using namespace imr::bench;
  static const std::vector<Subcommand> table = {
      {"engine", "[--frames N] [--seed S] [--quick] [--modes a,b,...]",
       "reconstruction engine on the synthetic street stream", &RunEngineBench},
      {"pipeline", "[--frames N] [--width W --height H] [--cores C] [--kitti DIR]",
       "the whole image pipeline (imr run) on one core: synthetic + KITTI", &RunPipelineBench},
      {"paper", "[--quick] [--modes ...] [--no-images] [--out DIR] ...",
       "the paper's comparison: accuracy and per-move overhead per policy", &RunPaperBench},
      {"scaling", "[--frames 250,500,1000,2000] [--out DIR] ...",
       "keyframe time, total time and memory against sequence length", &RunScalingBench},
      {"stream", "[--frames 20000] [--keyframe-every 5] [--keep-truth] ...",
       "the synthetic stream alone on the dense street (configs/dense-street.json):\n"
       "time per frame and memory per tenth of a long drive, observations, moves,\n"
       "track lengths; the scene's build time and Sees cost at both ends",
       &RunStreamBench},
      {"drive", "[--frames 20000] [--reference-frames 2000] [--no-long] ...",
       "long drives in bounded memory (issue 32): imr run on the dense street with and\n"
       "without engine.forget: peak RSS, its slope, frames/s per tenth, tiles, the\n"
       "surface beside the run without forgetting; the street stream both ways",
       &RunDriveBench},
#ifdef IMR_BENCH_EVALUATE
      {"peers", "[--frames N] [--colmap PATH]",
       "imr vs COLMAP's delaunay_mesher on identical input (needs\n"
       "tools/bench/peers/build_colmap.sh)",
       &RunPeersBench},
      {"quality", "[--inputs street,synth,kitti,stream] [--frames N] [--before IMR] ...",
       "surface quality per input (completeness, precision, F, distances,\n"
       "manifold, time, memory) beside the Piazza mesher and COLMAP",
       &RunQualityBench},
      {"planes", "--mesh MESH --sequence IMR_SYNTH_SEQ [--tolerance 0,0.1,0.2] ...",
       "engine.retriangulate_planes on one mesh per tolerance: regions, completeness,\n"
       "precision, roughness on the true planes",
       &RunPlanesBench},
      {"speed", "[--views-per-keyframe N] [--rounds N] [--work DIR]",
       "the engine on the street stream with every view a keyframe, one core\n"
       "and two, the fastest of N rounds each (issue 18's targets), with the\n"
       "time per phase",
       &RunSpeedBench},
      {"evaluate", "[--points N] [--triangles N] [--threads N] [--quick]",
       "imr evaluate's distances: 1 M points against a 500 k-triangle mesh", &RunEvaluateBench},
#endif
#ifdef IMR_BENCH_TEXTURE
      {"texture", "[--sequence DIR --mesh FILE] [--frames N] [--repeat N] [--atlas-size PX]",
       "colouring and texturing a mesh from its keyframe images: time per\n"
       "keyframe and per atlas megapixel, atlas size, added memory",
       &RunTextureBench},
#endif
  };
  return table;
}

// "  name options" (after `prefix`), then the description indented.
void PrintSubcommand(std::FILE* out, const char* prefix, const Subcommand& s) {
  std::fprintf(out, "%s%s %s\n         ", prefix, s.name, s.options);
  for (const char* c = s.description; *c; ++c)
    std::fputs(*c == '\n' ? "\n         " : std::string(1, *c).c_str(), out);
  std::fputc('\n', out);
}

void Usage(std::FILE* out) {
  std::fprintf(out, "usage: imr-bench <subcommand> [options]\nsubcommands:\n");
  for (const Subcommand& s : Subcommands()) PrintSubcommand(out, "  ", s);
}

bool IsHelp(const char* arg) { return !std::strcmp(arg, "--help") || !std::strcmp(arg, "-h"); }

}  // namespace

int main(int argc, char** argv) {
  imr::bench::ExeDir();  // resolved before anything can relink the binary (subprocess.h)
  if (argc < 2 || IsHelp(argv[1])) {
    Usage(argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  for (const Subcommand& s : Subcommands()) {
    if (argv[1] != std::string(s.name)) continue;
    for (int i = 2; i < argc; ++i)
      if (IsHelp(argv[i])) {
        PrintSubcommand(stdout, "usage: imr-bench ", s);
        std::printf("every option: tools/bench/%s_bench.cc\n", s.name);
        return 0;
      }
    return s.run(argc - 2, argv + 2);
  }
  std::fprintf(stderr, "imr-bench: unknown subcommand '%s'\n", argv[1]);
  Usage(stderr);
  return 2;
}
