use ignis_core::Size;
use ignis_volume::{FireScene, Preset};
fn main() {
    let p = match std::env::args().nth(1).as_deref() { Some("campfire") => Preset::Campfire, _ => Preset::Torch };
    let n: usize = std::env::args().nth(2).and_then(|a| a.parse().ok()).unwrap_or(5);
    let s = FireScene::preset(p).with_size(Size::new(256, 256).unwrap());
    for _ in 0..n { s.looping_animator(48).unwrap(); }
}
