//! The pipeline crate's documented channel table and shipped pipelines'
//! plans (`src/plans.md`, part of the `plan` module's docs) are what the
//! code resolves today. After a change to the table or the planner, rerun
//! with `MDTF_BLESS=1` to rewrite the page, and read its diff.

use mdtf_pipeline::channel::{Producer, TABLE};
use mdtf_pipeline::file::parse;
use mdtf_pipeline::run::{RunOptions, plan};
use std::path::Path;

/// The page as the code describes it.
fn rendered() -> String {
    let mut page = String::from(
        "## The channel table\n\n\
         Each row: the channel's name, who makes it (for a several-field input where that differs), what its \
         producer reads, its units and meaning. A field of the input is a channel named after the field; \
         `d{field}/d{x,y,z}` are the Jacobian's components.\n\n\
         | channel | made by | reads | units | meaning |\n|---|---|---|---|---|\n",
    );
    let producer = |p: Producer| match p {
        Producer::Input => "input".to_string(),
        Producer::Derive(item) => format!("derive `{}`", item.name()),
        Producer::DeriveFields(item) => format!("derive over the fields `{}`", item.name()),
        Producer::Prefilter => "pre-filter".to_string(),
        Producer::Trace => "tracing".to_string(),
    };
    for r in &TABLE {
        let made_by = match r.multi {
            Some((p, _)) => format!("{}; several fields: {}", producer(r.producer), producer(p)),
            None => producer(r.producer),
        };
        let reads: Vec<String> = r.prerequisites.iter().map(|c| c.name(&[])).collect();
        let reads = if reads.is_empty() { "-".to_string() } else { reads.join(" ") };
        let meaning = r.text.meaning.replace('|', "\\|");
        page += &format!("| `{}` | {made_by} | {reads} | {} | {meaning} |\n", r.name, r.text.units);
    }
    page += "\n## The plans of the shipped pipelines\n\nAs `mdtf run PIPELINE.toml --plan` prints them, on each \
             pipeline's own input.\n";
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines");
    let mut files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    files.retain(|f| f.extension().is_some_and(|e| e == "toml"));
    files.sort();
    for f in files {
        let p = parse(&std::fs::read_to_string(&f).unwrap(), &[]).unwrap();
        let opts = RunOptions { pipeline_path: f.clone(), ..Default::default() };
        let (plan, input, geo) = plan(&mdtf_pipeline::settings::Settings::new(&p, &opts)).unwrap();
        let name = f.file_name().unwrap().to_string_lossy();
        let [nx, ny, nz] = geo.dims;
        page += &format!("\n### `{name}` ({input}, {nx} x {ny} x {nz})\n\n```text\n{plan}\n```\n");
    }
    page
}

#[test]
fn the_documented_table_and_plans_are_the_code_s() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/plans.md");
    let page = rendered();
    if std::env::var_os("MDTF_BLESS").is_some() {
        std::fs::write(&path, &page).unwrap();
    }
    let doc = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        doc == page,
        "src/plans.md is not what the code resolves; rerun with MDTF_BLESS=1 and read the diff:\n{page}"
    );
}
