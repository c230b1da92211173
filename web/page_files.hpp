// The observer page as the bridge serves it: the files the build bundles into one folder
// (web/page/bundle.mjs: index.html, app.js with three.js inside, style.css), read once at start
// and served from memory. Only these names are served: no directory walking, nothing fetched
// from elsewhere at run time.
#pragma once

#include <string>
#include <vector>

namespace neurosim::web {

struct PageFile {
  std::string path;          // URL path, e.g. "/app.js"
  std::string content_type;  // e.g. "text/javascript; charset=utf-8"
  std::string body;
};

class PageFiles {
 public:
  // The names every bundle has.
  static const std::vector<std::string>& names();
  // Reads every name from `dir`. Throws std::runtime_error naming the first missing or unreadable
  // file (and the target that builds it).
  static PageFiles load(const std::string& dir);

  const std::vector<PageFile>& files() const { return files_; }
  // The file for a URL path ("/" is "/index.html"), or null.
  const PageFile* find(const std::string& url_path) const;
  // index.html with "{{query}}" (where the page's own URLs take the token) replaced by `query`,
  // e.g. "?token=..." or "".
  std::string index_html(const std::string& query) const;

 private:
  std::vector<PageFile> files_;
};

}  // namespace neurosim::web
