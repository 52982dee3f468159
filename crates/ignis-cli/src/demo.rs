//! `ignis demo`: the main job on built-in defaults. Each method adds a section of results
//! to a gallery; the run ends by writing `DIR/index.html` and listing what it wrote.

use crate::global::Global;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// One result shown in the gallery.
#[derive(Clone, Debug)]
pub struct Item {
    /// Path relative to the demo directory.
    pub file: String,
    /// What it is.
    pub caption: String,
    /// The settings that made it (shown under the result).
    pub settings: String,
}

/// A titled group of results, one per method.
#[derive(Clone, Debug)]
pub struct Section {
    pub title: String,
    pub text: String,
    pub items: Vec<Item>,
}

/// The demo run: where to write, and the gallery so far.
/// `../shared/data/<name>` (relative to the working directory or to the source tree),
/// when present.
pub fn shared_data(name: &str) -> Option<PathBuf> {
    [
        PathBuf::from("../shared/data").join(name),
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(name),
    ]
    .into_iter()
    .find(|p| p.is_file())
}

pub struct Demo {
    /// Where results are written now: a hidden staging directory beside the output,
    /// moved into place by [`Demo::finish`] (a failed demo leaves nothing new).
    pub dir: PathBuf,
    /// The output directory the user named.
    final_dir: PathBuf,
    staged: Option<crate::output::StagedDir>,
    pub global: Global,
    /// Seed for every generator in the demo.
    pub seed: u64,
    /// Smaller sizes and fewer frames (used by tests).
    pub quick: bool,
    pub sections: Vec<Section>,
}

impl Demo {
    pub fn new(dir: &Path, global: Global, seed: u64, quick: bool) -> Result<Demo> {
        let staged = crate::output::StagedDir::new(dir)
            .with_context(|| format!("creating demo directory {}", dir.display()))?;
        Ok(Demo {
            dir: staged.path().to_path_buf(),
            final_dir: dir.to_path_buf(),
            staged: Some(staged),
            global,
            seed,
            quick,
            sections: Vec::new(),
        })
    }

    /// Starts a new section.
    pub fn section(&mut self, title: &str, text: &str) {
        self.global.say(format!("== {title}"));
        self.sections.push(Section {
            title: title.into(),
            text: text.into(),
            items: Vec::new(),
        });
    }

    /// Path of a file in the demo directory (its parent is created).
    pub fn path(&self, rel: &str) -> Result<PathBuf> {
        let p = self.dir.join(rel);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        Ok(p)
    }

    /// Adds a written result to the current section.
    pub fn item(&mut self, rel: &str, caption: &str, settings: &str) {
        self.global
            .say(format!("  wrote {}", self.final_dir.join(rel).display()));
        if self.sections.is_empty() {
            self.section("Results", "");
        }
        let s = self.sections.last_mut().expect("a section");
        s.items.push(Item {
            file: rel.into(),
            caption: caption.into(),
            settings: settings.into(),
        });
    }

    /// Writes `index.html`, moves everything into the output directory and returns the
    /// index's path.
    pub fn finish(mut self) -> Result<PathBuf> {
        let mut html = String::from(
            "<!doctype html><html><head><meta charset=\"utf-8\"><title>Ignis demo</title><style>\
             body{background:#111;color:#ddd;font-family:sans-serif;margin:2em}\
             .grid{display:flex;flex-wrap:wrap;gap:1.5em}.card{background:#1c1c1c;padding:1em;border-radius:6px;max-width:520px}\
             img,video{max-width:480px;max-height:480px;background:#000;display:block}\
             video.keyed{background:repeating-conic-gradient(#777 0 25%,#bbb 0 50%) 0 0/24px 24px}\
             code{color:#fb4;font-size:0.85em;white-space:pre-wrap}a{color:#fb4}</style></head><body>\
             <h1>Ignis demo</h1><p>Every result below was made by <code>ignis demo</code> on built-in defaults.</p>",
        );
        for s in &self.sections {
            html.push_str(&format!(
                "<h2>{}</h2><p>{}</p><div class=\"grid\">",
                esc(&s.title),
                esc(&s.text)
            ));
            for it in &s.items {
                let f = esc(&it.file);
                let media = if it.file.ends_with(".mp4") {
                    format!("<video src=\"{f}\" controls loop muted autoplay></video>")
                } else if it.file.ends_with(".webm") {
                    format!(
                        "<video class=\"keyed\" src=\"{f}\" controls loop muted autoplay></video>"
                    )
                } else if it.file.ends_with(".png")
                    || it.file.ends_with(".gif")
                    || it.file.ends_with(".jpg")
                {
                    format!("<a href=\"{f}\"><img src=\"{f}\" alt=\"{f}\"></a>")
                } else {
                    String::new()
                };
                html.push_str(&format!(
                    "<div class=\"card\">{media}<p><a href=\"{f}\">{f}</a> — {}</p><code>{}</code></div>",
                    esc(&it.caption),
                    esc(&it.settings)
                ));
            }
            html.push_str("</div>");
        }
        html.push_str("</body></html>\n");
        let path = self.dir.join("index.html");
        std::fs::write(&path, html).with_context(|| format!("writing {}", path.display()))?;
        if let Some(s) = self.staged.take() {
            s.commit()?;
        }
        Ok(self.final_dir.join("index.html"))
    }
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
