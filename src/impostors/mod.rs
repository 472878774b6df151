//! Multi-cell orthographic impostors (multi-cell-orthographic-impostors.txt): the cells and
//! their captured images (`build`) and the views composed from them (`view`).

pub mod build;
pub mod view;
