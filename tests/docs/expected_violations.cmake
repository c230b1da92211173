# What cmake/check_docs.cmake must report on fixtures/bad (tests/expect_violations.cmake): each
# planted violation (a missing path named or linked, an unnamed source, a source in no section),
# and nothing else.
set(WHAT "docs check")
set(EXPECTED
  "docs/ARCHITECTURE.md:3: names `lib/missing.cpp`, which does not exist"
  "docs/ARCHITECTURE.md:3: names `ghost.hpp`, which does not exist"
  "docs/ARCHITECTURE.md:3: links docs/nothere.md, which does not exist"
  "docs/ARCHITECTURE.md:9: names `gone.hpp`, which does not exist"
  "lib/README.md:2: names `also_gone.cpp`, which does not exist"
  "lib/README.md:2: names `sub/`, which does not exist"
  "lib/orphan.cpp: not named in the section \"### lib\""
  "loose/b.cpp: in no component section"
  "docs: 8 violation(s)")
set(CLEAN "lib/a.cpp" "lib/a.hpp" "`lib/a.*`" "`a.*`" "`a.cpp`")
