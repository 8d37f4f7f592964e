"""The README's Python API example runs as written (it documents what the code does)."""

from pathlib import Path
import re

import pytest

README = Path(__file__).resolve().parent.parent / 'README.md'


@pytest.mark.slow
def test_python_api_example_runs():
    text = README.read_text(encoding='utf-8')
    section = text[text.index('## Python API'):]
    code = re.search(r'```python\n(.*?)```', section, re.S).group(1)
    namespace = {}
    exec(compile(code, 'README.md (Python API)', 'exec'), namespace)  # noqa: S102
    result = namespace['result']
    assert len(namespace['table']) == 2 and namespace['hit'] is not None
    assert result.locks == {'right_arm_joint4': 0.0}
    assert result.success and result['circle'].method == 'per_point'
    assert namespace['res'].fun < 1e-3
