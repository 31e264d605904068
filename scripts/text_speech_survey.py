"""What espeak-ng says for a chatbot's answers before and after the text normalisation (session text50).

    python scripts/text_speech_survey.py [--lang en|es] [--changed]

For each line below (realistic language-model answers: URLs, e-mails, dates, times, amounts, units, versions,
ordinals, phone numbers, hashtags, emoji, abbreviations, ranges), prints the text espeak-ng is given and its
phonemes (``espeak-ng -x -q``, the voice facecast uses by default) as the text path was before
(:func:`realtime_core.synthesis.text.clean_text` without a language) and now (with it:
:func:`realtime_core.synthesis.text.normalise_for_speech`). ``--changed``: only the lines the normalisation
rewrites.
"""

from __future__ import annotations

import argparse
import subprocess

from realtime_core.synthesis.text import clean_text

LINES = {
    "en": [
        "You can find the docs at https://docs.python.org/3/library/re.html.",
        "Visit example.com for details.",
        "Go to www.github.com/facecast/issues?state=open&sort=new to see open issues.",
        "Check http://localhost:8080/api/v1 in your browser.",
        "Email support@example.com or john.doe@company.co.uk.",
        "The release is scheduled for 2026-12-07.",
        "The meeting is on 12/07/2026 at 14:30.",
        "It starts Dec 7 at 2:30 pm.",
        "The deadline is December 7th, 2026.",
        "That costs $5, or $19.99 with shipping.",
        "The ticket is 3.50 EUR, about €20 for two.",
        "Sales grew 12.5% last year.",
        "It's a 5 km run and it's 20°C outside.",
        "You need 3 GB of RAM and 500 MB of disk.",
        "Upgrade to v2.1.3 or later.",
        "This requires Python 3.12 and Node 20.",
        "She finished 1st, he was 2nd and I was 3rd.",
        "Call +1 (555) 123-4567 or 555-0199.",
        "Follow us @facecast and use #MachineLearning.",
        "Great job! 🎉 Let's go 🚀",
        "Bring fruit, e.g., apples, pears, etc.",
        "Dr. Smith will see you at 9 a.m.",
        "Expect 10-20 minutes of waiting.",
        "Pages 5–10 cover the basics.",
        "It's open 9:00-17:00, Mon-Fri.",
        "The file is at /usr/local/bin/python.",
        "Temperatures range from -5°C to 10°C.",
        "Read the FAQ at https://example.com/faq#pricing.",
        "Use Ctrl+C to stop.",
        "Version 1.0 was released in Q3 2024.",
        "The call is at 9:05 am on 3/4.",
        "It weighs 2.5 kg and is 30 cm long.",
        "The report from Jan 15, 2025 is ready.",
        "See https://en.wikipedia.org/wiki/Speech_synthesis for background.",
    ],
    "es": [
        "Puedes ver la documentación en https://docs.python.org/3/.",
        "Visita www.ejemplo.es para más información.",
        "Escríbenos a soporte@ejemplo.com.",
        "La reunión es el 07/12/2026 a las 14:30.",
        "La fecha límite es el 2026-12-07.",
        "Empieza el 7 de diciembre a las 9:00.",
        "Cuesta 3,50 € o 20 EUR.",
        "El precio es de $5.",
        "Las ventas subieron un 12,5%.",
        "Hace 20°C y caminamos 5 km.",
        "Necesitas 3 GB de memoria.",
        "Actualiza a la v2.1.3.",
        "Requiere Python 3.12.",
        "Llegó en 1.º lugar y ella en 2.ª posición.",
        "Llama al +34 912 345 678.",
        "Síguenos en @facecast con #IA.",
        "Trae frutas, p. ej., manzanas, peras, etc.",
        "La Dra. García te atenderá a las 10:30 h.",
        "Tardará entre 10-20 minutos.",
        "¡Genial! 🎉",
        "Abre de 9:00 a 17:00.",
        "Es el 1 de enero.",
        "Consulta http://localhost:8080/api en tu navegador.",
        "Nos vemos el 15/01/2025 a las 9:05.",
    ],
}
VOICE = {"en": "en-us", "es": "es"}


def phonemes(text: str, voice: str) -> str:
    """espeak-ng's phoneme mnemonics for ``text`` (its ``-x`` output, lines joined)."""
    out = subprocess.run(["espeak-ng", "-q", "-x", "-v", voice, text], capture_output=True, text=True, check=True)
    return " ".join(out.stdout.split())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lang", choices=sorted(LINES), action="append", help="default: both")
    ap.add_argument("--changed", action="store_true", help="only the lines the normalisation rewrites")
    args = ap.parse_args()
    for lang in args.lang or sorted(LINES):
        for line in LINES[lang]:
            before, after = clean_text(line), clean_text(line, language=lang)
            if args.changed and before == after:
                continue
            print(f"[{lang}] {line}")
            print(f"   before: {before}\n           {phonemes(before, VOICE[lang])}")
            if after != before:
                print(f"   after:  {after}\n           {phonemes(after, VOICE[lang])}")


if __name__ == "__main__":
    main()
