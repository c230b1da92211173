// fuzz_mutate: a fixed set of inputs made from a seed corpus, the same on every machine and in
// every run (what the ctest fuzz_libfuzzer feeds each sanitized target: its verdict then cannot
// depend on the machine's speed, load or address layout, as a coverage-guided search's does).
//
//   fuzz_mutate --seed S --count N [--dict FILE] --out DIR CORPUS_DIR
//
// Writes DIR/mutant_<k> for k < N: a corpus file (sorted by name) chosen by the generator, then
// 1 to 4 edits: flip a bit, set a byte to an interesting value, insert or erase bytes, duplicate a
// range, splice in a part of another corpus file, insert a dictionary token (libFuzzer's
// dictionary format: one "token" per line). The generator is splitmix64 with raw outputs, not
// <random>'s distributions (whose results differ between standard libraries).
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

struct SplitMix64 {
  std::uint64_t s;
  std::uint64_t next() {
    std::uint64_t z = (s += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  std::size_t below(std::size_t n) { return n == 0 ? 0 : static_cast<std::size_t>(next() % n); }
};

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Tokens of a libFuzzer dictionary: the text between the first and last quote of each line
// (escapes \\xNN, \\" and \\\\ decoded).
std::vector<std::string> read_dict(const fs::path& p) {
  std::vector<std::string> tokens;
  std::ifstream in(p);
  std::string line;
  while (std::getline(in, line)) {
    const auto a = line.find('"'), b = line.rfind('"');
    if (line.empty() || line[0] == '#' || a == std::string::npos || b <= a) continue;
    std::string t;
    for (std::size_t i = a + 1; i < b; ++i) {
      if (line[i] == '\\' && i + 1 < b) {
        if (line[i + 1] == 'x' && i + 3 < b) {
          t += static_cast<char>(std::strtol(line.substr(i + 2, 2).c_str(), nullptr, 16));
          i += 3;
        } else {
          t += line[++i];
        }
      } else {
        t += line[i];
      }
    }
    tokens.push_back(t);
  }
  return tokens;
}

void mutate(std::string& d, SplitMix64& rng, const std::vector<std::string>& corpus,
            const std::vector<std::string>& dict) {
  static const char kInteresting[] = {0, '\xff', '\x7f', '\x80', '0', '1', '9', '-', '.', 'e',
                                      ' ', '\n', '{', '}', '"', ':'};
  const std::size_t edits = 1 + rng.below(4);
  for (std::size_t e = 0; e < edits; ++e) {
    const std::size_t pos = rng.below(d.size() + 1);
    switch (rng.below(dict.empty() ? 6 : 7)) {
      case 0:  // flip a bit
        if (!d.empty()) d[rng.below(d.size())] ^= static_cast<char>(1u << rng.below(8));
        break;
      case 1:  // an interesting byte
        if (!d.empty()) d[rng.below(d.size())] = kInteresting[rng.below(sizeof kInteresting)];
        break;
      case 2:  // insert random bytes
        d.insert(pos, std::string(1 + rng.below(8), static_cast<char>(rng.next())));
        break;
      case 3:  // erase a range
        if (pos < d.size()) d.erase(pos, 1 + rng.below(std::min<std::size_t>(d.size() - pos, 64)));
        break;
      case 4:  // duplicate a range
        if (pos < d.size()) {
          const std::string part = d.substr(pos, 1 + rng.below(std::min<std::size_t>(d.size() - pos, 256)));
          d.insert(rng.below(d.size() + 1), part);
        }
        break;
      case 5: {  // splice a part of another corpus file
        const std::string& o = corpus[rng.below(corpus.size())];
        if (!o.empty()) {
          const std::size_t from = rng.below(o.size());
          d.insert(pos, o.substr(from, 1 + rng.below(std::min<std::size_t>(o.size() - from, 256))));
        }
        break;
      }
      default:  // a dictionary token
        d.insert(pos, dict[rng.below(dict.size())]);
    }
  }
  if (d.size() > (1u << 20)) d.resize(1u << 20);
}

}  // namespace

int main(int argc, char** argv) {
  std::uint64_t seed = 1;
  long count = -1;
  fs::path dict_file, out, corpus_dir;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "fuzz_mutate: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--seed") seed = std::strtoull(value().c_str(), nullptr, 10);
    else if (a == "--count") count = std::strtol(value().c_str(), nullptr, 10);
    else if (a == "--dict") dict_file = value();
    else if (a == "--out") out = value();
    else corpus_dir = a;
  }
  if (count < 0 || out.empty() || corpus_dir.empty() || !fs::is_directory(corpus_dir)) {
    std::cerr << "usage: fuzz_mutate --seed S --count N [--dict FILE] --out DIR CORPUS_DIR\n";
    return 2;
  }
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(corpus_dir))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) {
    std::cerr << "fuzz_mutate: " << corpus_dir.string() << ": no seed inputs\n";
    return 1;
  }
  std::vector<std::string> corpus;
  for (const auto& f : files) corpus.push_back(slurp(f));
  const std::vector<std::string> dict = dict_file.empty() ? std::vector<std::string>{} : read_dict(dict_file);
  fs::create_directories(out);
  SplitMix64 rng{seed};
  for (long k = 0; k < count; ++k) {
    std::string d = corpus[rng.below(corpus.size())];
    mutate(d, rng, corpus, dict);
    std::ofstream(out / ("mutant_" + std::to_string(k)), std::ios::binary).write(d.data(), static_cast<std::streamsize>(d.size()));
  }
  return 0;
}
