#include "web/page_files.hpp"

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace neurosim::web {

namespace {

std::string content_type(const std::string& name) {
  const auto dot = name.rfind('.');
  const std::string ext = dot == std::string::npos ? "" : name.substr(dot + 1);
  if (ext == "html") return "text/html; charset=utf-8";
  if (ext == "js") return "text/javascript; charset=utf-8";
  if (ext == "css") return "text/css; charset=utf-8";
  return "application/octet-stream";
}

}  // namespace

const std::vector<std::string>& PageFiles::names() {
  static const std::vector<std::string> n{"index.html", "app.js", "style.css"};
  return n;
}

PageFiles PageFiles::load(const std::string& dir) {
  PageFiles p;
  for (const std::string& name : names()) {
    const std::string file = dir + "/" + name;
    std::ifstream in(file, std::ios::binary);
    if (!in)
      throw std::runtime_error("page file " + file +
                               " missing (the build's neurosim_web_page target bundles it; "
                               "--page-dir picks another folder)");
    std::ostringstream text;
    text << in.rdbuf();
    p.files_.push_back(PageFile{"/" + name, content_type(name), text.str()});
  }
  return p;
}

const PageFile* PageFiles::find(const std::string& url_path) const {
  const std::string path = url_path == "/" ? "/index.html" : url_path;
  for (const PageFile& f : files_)
    if (f.path == path) return &f;
  return nullptr;
}

std::string PageFiles::index_html(const std::string& query) const {
  const PageFile* f = find("/index.html");
  if (f == nullptr) return {};
  std::string html = f->body;
  const std::string key = "{{query}}";
  for (auto p = html.find(key); p != std::string::npos; p = html.find(key, p + query.size()))
    html.replace(p, key.size(), query);
  return html;
}

}  // namespace neurosim::web
