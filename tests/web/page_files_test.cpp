// PageFiles: the bundle the build made is complete, only its names are served, index.html
// takes the token query, a missing file is named.
#include "web/page_files.hpp"

#include "test_support.hpp"
#include "web/options.hpp"

#include <gtest/gtest.h>

#include <fstream>

namespace web = neurosim::web;
namespace nt = neurosim::testing;

TEST(PageFiles, TheBuiltBundleIsCompleteAndSelfContained) {
  const web::PageFiles p = web::PageFiles::load(web::default_page_dir());
  ASSERT_EQ(p.files().size(), 3U);
  const web::PageFile* app = p.find("/app.js");
  ASSERT_NE(app, nullptr);
  EXPECT_EQ(app->content_type, "text/javascript; charset=utf-8");
  EXPECT_GT(app->body.size(), 100000U);  // three.js is inside
  EXPECT_NE(app->body.find("neurosimWeb"), std::string::npos);
  // Nothing is loaded from elsewhere at run time: no absolute URL in the page's own markup, and
  // no import of another module from the bundle.
  const std::string html = p.index_html("?token=abc");
  EXPECT_EQ(html.find("http://"), std::string::npos);
  EXPECT_EQ(html.find("https://"), std::string::npos);
  EXPECT_NE(html.find("src=\"app.js?token=abc\""), std::string::npos);
  EXPECT_NE(html.find("href=\"style.css?token=abc\""), std::string::npos);
  EXPECT_EQ(html.find("{{query}}"), std::string::npos);
  EXPECT_EQ(app->body.find("import("), std::string::npos);
  EXPECT_EQ(p.find("/"), p.find("/index.html"));
  EXPECT_EQ(p.find("/../CMakeCache.txt"), nullptr);
  EXPECT_EQ(p.find("/package.json"), nullptr);
}

TEST(PageFiles, MissingFileIsNamed) {
  const auto dir = nt::temp_dir("web_page");
  std::ofstream(dir / "index.html") << "x";
  EXPECT_NE(nt::message_of([&] {
              web::PageFiles::load(dir.string());
            }).find("page file " + (dir / "app.js").string() + " missing"),
            std::string::npos);
}
