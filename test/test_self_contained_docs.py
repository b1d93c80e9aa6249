"""The project documents itself: no file cites documents that users do not have.

The model is described in ``docs/model.md``; development-machine paths and
the development team's spec files must not appear in any tracked file.
"""

import re
import shutil
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# written in pieces so that this file does not match itself
FORBIDDEN = ['model' + '_spec', '..' + '/shared', '/work' + '/shared']
_SKIP_DIRS = {'.git', '.venv', 'venv', 'build', 'install', 'log', '__pycache__',
              '.pytest_cache', '.hypothesis', '.ruff_cache'}


def tracked_files():
    """Files under version control (``git ls-files``), or every source file without git."""
    if shutil.which('git') and (REPO / '.git').exists():
        out = subprocess.run(['git', 'ls-files', '-z'], cwd=REPO, capture_output=True,
                             check=True).stdout
        return [REPO / p for p in out.decode().split('\0') if p]
    return [p for p in REPO.rglob('*') if p.is_file()
            and not _SKIP_DIRS.intersection(p.relative_to(REPO).parts)
            and not any(part.endswith('.egg-info') for part in p.parts)]


def test_no_file_cites_documents_users_do_not_have():
    pattern = re.compile('|'.join(re.escape(f) for f in FORBIDDEN))
    offenders = []
    files = tracked_files()
    assert len(files) > 20
    for path in files:
        try:
            text = path.read_text(encoding='utf-8')
        except (UnicodeDecodeError, OSError):
            continue
        for i, line in enumerate(text.splitlines(), 1):
            if pattern.search(line):
                offenders.append(f'{path.relative_to(REPO)}:{i}: {line.strip()}')
    assert not offenders, 'cite docs/model.md instead:\n' + '\n'.join(offenders)


def test_model_doc_exists_and_covers_what_it_promises():
    text = (REPO / 'docs' / 'model.md').read_text()
    for heading in ('## 1. Frames and conventions', '## 5. The default robot',
                    '## 6. Choices the paper leaves open', '## 7. Validation'):
        assert heading in text, heading
    # every value of the default robot file is in the table with its source
    for value in ('0.0963 m', '576.94 lam + 28.9', '8.087 mm', '17.90 mm', '20 mm',
                  '0.20 kg/m', '-50 .. 150 kPa', '-50 .. 120 kPa'):
        assert value in text, value


def test_citations_of_model_doc_point_to_existing_sections():
    """``docs/model.md section N`` citations name sections that exist."""
    text = (REPO / 'docs' / 'model.md').read_text()
    sections = {int(n) for n in re.findall(r'^## (\d+)\.', text, re.M)}
    cited = []
    for path in tracked_files():
        if path.suffix not in ('.py', '.md', '.yaml', '.txt'):
            continue
        body = path.read_text(encoding='utf-8').replace('\n', ' ')
        for n in re.findall(r'docs/model\.md`?,?\s+section\s+(\d+)', body):
            cited.append((path.name, int(n)))
    assert cited, 'no citation found'
    missing = [(name, n) for name, n in cited if n not in sections]
    assert not missing, missing
