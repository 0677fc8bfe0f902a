"""Pipeline.render_views: the views of a split rendered for evaluation and pictures."""

from __future__ import annotations

from pathlib import Path

from tests.helpers import train_tiny


def test_render_views_renders_only_the_named_views(tmp_path: Path) -> None:
    trainer, _ = train_tiny(tmp_path, iters=5)
    pipeline = trainer.pipeline
    names = [view.name for view in pipeline.datamanager.eval_views("test")]
    rendered = []
    render_rays = pipeline.model.render_rays

    def counting(*args: object, **kwargs: object) -> dict:
        rendered.append(1)
        return render_rays(*args, **kwargs)

    pipeline.model.render_rays = counting
    assert [r.view.name for r in pipeline.render_views("test", 5, [names[-1]])] == [names[-1]]
    assert len(rendered) == 1, "the views not named are skipped, not rendered and dropped"
    assert [r.view.name for r in pipeline.render_views("test", 5)] == names, "no names: every view"
