//! volgen's research programs, one example each (`research/examples/`): the measurements that
//! docs/journal/ records, kept runnable so an entry can be re-run
//! (`cargo run --release -p research --example NAME`). Nothing here is a library API.
