// Command lines through neurosim::cli: --help and --version exit 0, every usage error is
// "<program>: <message>" + the --help hint with status 2, number checks name the option.
#include "common/cli.hpp"

#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace cli = neurosim::cli;

namespace {

struct Outcome {
  std::optional<int> rc;
  std::string out, err;
};

struct Options {
  double duration = 0;
  int domain = -1;
  std::array<double, 3> origin{0, 0, 0};
  bool flag = false;
  std::string name = "x";
};

Outcome run(std::vector<const char*> args, Options& o) {
  args.insert(args.begin(), "prog");
  cli::Parser p("prog", "A test program.");
  p.add_option("--duration", o.duration, "seconds")->check(cli::positive());
  p.add_option("--domain", o.domain, "domain")->check(cli::in_range(0, 230));
  p.add_option("--name", o.name, "name");
  p.add_triple("--origin", o.origin, "point");
  p.add_flag("--flag", o.flag, "a flag");
  p.check([&] {
    if (o.flag && o.name == "x") throw cli::UsageError("--flag needs --name");
  });
  std::ostringstream out, err;
  Outcome r;
  r.rc = p.parse(static_cast<int>(args.size()), args.data(), out, err);
  r.out = out.str();
  r.err = err.str();
  return r;
}

}  // namespace

TEST(common_cli, GoodCommandLineRuns) {
  Options o;
  const Outcome r = run({"--duration", "2.5", "--domain", "7", "--origin", "-0.1,0,1e-3", "--name",
                     "y", "--flag"},
                    o);
  EXPECT_FALSE(r.rc.has_value()) << r.err;
  EXPECT_EQ(o.duration, 2.5);
  EXPECT_EQ(o.domain, 7);
  EXPECT_EQ(o.origin[0], -0.1);
  EXPECT_EQ(o.origin[2], 1e-3);
  EXPECT_TRUE(o.flag);
  Options last;
  EXPECT_FALSE(run({"--duration", "1", "--duration", "3"}, last).rc.has_value());
  EXPECT_EQ(last.duration, 3.0) << "the last value wins";
}

TEST(common_cli, HelpAndVersionExitZero) {
  Options o;
  const Outcome h = run({"--help"}, o);
  ASSERT_EQ(h.rc, 0);
  EXPECT_NE(h.out.find("--duration"), std::string::npos) << h.out;
  EXPECT_NE(h.out.find("--version"), std::string::npos) << h.out;
  const Outcome v = run({"--version"}, o);
  ASSERT_EQ(v.rc, 0);
  EXPECT_EQ(v.out, std::string("prog ") + cli::version() + "\n");
  EXPECT_FALSE(std::string(cli::version()).empty());
}

TEST(common_cli, UsageErrorsExitTwoInOneStyle) {
  const std::vector<std::vector<const char*>> bad = {
      {"--duration", "-1"},   {"--duration", "0"},      {"--duration", "nan"},
      {"--duration", "inf"},  {"--duration", "abc"},    {"--duration"},
      {"--domain", "231"},    {"--domain", "-1"},       {"--bogus"},
      {"--origin", "1,2"},    {"--origin", "1,2,x"},    {"--origin", "1,2,3,4"},
      {"--flag"},             {"positional"}};
  for (const auto& args : bad) {
    Options o;
    const Outcome r = run(args, o);
    std::string joined;
    for (const char* a : args) joined += std::string(a) + " ";
    ASSERT_EQ(r.rc, cli::kUsageError) << joined;
    EXPECT_EQ(r.err.rfind("prog: ", 0), 0u) << joined << ": " << r.err;
    EXPECT_NE(r.err.find("\nRun with --help for more information.\n"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
  }
  Options o;
  EXPECT_NE(run({"--duration", "-1"}, o).err.find("--duration"), std::string::npos);
  EXPECT_NE(run({"--domain", "999"}, o).err.find("[0, 230]"), std::string::npos);
  EXPECT_NE(run({"--bogus"}, o).err.find("--bogus"), std::string::npos);
  EXPECT_NE(run({"--duration"}, o).err.find("prog: --duration needs a value"), std::string::npos);
  EXPECT_NE(run({"--origin", "1,2"}, o).err.find("X,Y,Z"), std::string::npos);
  EXPECT_NE(run({"--flag"}, o).err.find("--flag needs --name"), std::string::npos);
}

TEST(common_cli, ParseOrThrowForLibraryParsers) {
  double d = 1;
  cli::Parser p("prog");
  p.add_option("--d", d)->check(cli::non_negative());
  const char* ok[] = {"prog", "--d", "0"};
  EXPECT_TRUE(p.parse_or_throw(3, ok));
  EXPECT_EQ(d, 0.0);
  const char* bad[] = {"prog", "--d", "-2"};
  try {
    p.parse_or_throw(3, bad);
    FAIL() << "no error";
  } catch (const cli::UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("--d"), std::string::npos) << e.what();
  }
  EXPECT_EQ(cli::parse_triple("--o", "1,2,3")[1], 2.0);
  EXPECT_THROW(cli::parse_triple("--o", "1,,3"), cli::UsageError);
  EXPECT_THROW(cli::parse_triple("--o", "1,2,inf"), cli::UsageError);
}

// The CLI11 pieces behind the header: its checks, option functions, repeated options.
TEST(common_cli, ChecksAndOptionFunctionsBehindTheHeader) {
  const auto parse = [](cli::Parser& p, std::vector<const char*> args) {
    args.insert(args.begin(), "prog");
    std::ostringstream out, err;
    const auto rc = p.parse(static_cast<int>(args.size()), args.data(), out, err);
    return std::make_pair(rc, out.str() + err.str());
  };
  std::string mode, size;
  int every = 1;
  std::vector<std::string> files;
  cli::Parser p("prog");
  p.add_option("--mode", mode)->check(cli::one_of({"event", "clock"}));
  p.add_option("--every", every)->check(cli::range(1, 10))->capture_default_str();
  p.add_option("--file", files)->take_all();
  p.add_option_function<std::string>("--size", [&](const std::string& v) {
    if (v.find('x') == std::string::npos) throw cli::UsageError("--size: expected WxH");
    size = v;
  });
  const auto help = parse(p, {"--help"});
  EXPECT_EQ(help.first, 0);
  EXPECT_NE(help.second.find("INT in [1 - 10]"), std::string::npos) << help.second;
  EXPECT_NE(help.second.find("{event,clock}"), std::string::npos) << help.second;
  const auto good =
      parse(p, {"--mode", "clock", "--every", "3", "--file", "a", "--file", "b", "--size", "4x3"});
  EXPECT_FALSE(good.first.has_value()) << good.second;
  EXPECT_EQ(mode, "clock");
  EXPECT_EQ(every, 3);
  EXPECT_EQ(files, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(size, "4x3");
  EXPECT_EQ(p.count("--file"), 2u);
  for (const auto& [args, message] :
       std::vector<std::pair<std::vector<const char*>, std::string>>{
           {{"--mode", "fast"}, "fast not in {event,clock}"},
           {{"--every", "11"}, "--every: Value 11 not in range 1 to 10"},
           {{"--size", "43"}, "prog: --size: expected WxH\n"}}) {
    const auto bad = parse(p, args);
    EXPECT_EQ(bad.first, cli::kUsageError) << message;
    EXPECT_NE(bad.second.find(message), std::string::npos) << bad.second;
  }
}
